"""The harness's layout: a library that never imports its command line, and subcommands all
defined the same way (one module each in juno.commands)."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import juno
from juno.commands import COMMANDS

PACKAGE = Path(juno.__file__).parent
#: Every module of the library, its subpackages' (juno.diagnose) too; not the command line (cli.py,
#: __main__.py, juno.commands).
LIBRARY_MODULES = sorted(p for p in PACKAGE.rglob("*.py") if p.name not in ("cli.py", "__main__.py")
                         and p.relative_to(PACKAGE).parts[0] != "commands")


def _module_name(path: Path) -> str:
    """The dotted name of the library module at ``path`` (a package's __init__.py is the package)."""
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return ".".join(("juno",) + (parts[:-1] if parts[-1] == "__init__" else parts))


def _imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, as written (relative imports keep their dots)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            prefix = base if base.endswith(".") else base + "."
            names.add(base)
            names.update(prefix + a.name for a in node.names)
    return names


@pytest.mark.parametrize("path", LIBRARY_MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_the_library_never_imports_the_command_line(path):
    """No library module imports juno.cli or juno.commands (not even inside a function)."""
    imported = _imported_modules(path)
    bad = sorted(n for n in imported if n.lstrip(".").split(".")[0] in ("cli", "commands")
                 or n.startswith(("juno.cli", "juno.commands")))
    assert not bad, f"{path.name} imports {bad}"


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_subcommand_module_has_the_same_interface(name):
    """HELP (text), OUTPUTS (argument -> kind of output), add_arguments(parser), run(args)."""
    module = COMMANDS[name]
    assert isinstance(module.HELP, str) and module.HELP
    assert set(module.OUTPUTS.values()) <= {"file", "report", "plots", "campaign"}
    assert callable(module.add_arguments) and callable(module.run)


def test_every_subcommand_is_on_the_command_line():
    """``juno --help`` lists exactly the modules of juno.commands, and each declared output is an
    option of its parser."""
    from juno.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert list(sub.choices) == list(COMMANDS)
    for name, p in sub.choices.items():
        dests = {a.dest for a in p._actions}
        assert set(COMMANDS[name].OUTPUTS) <= dests, name
        assert {"json", "fmu", "quiet", "force"} <= dests, name


def test_the_package_imports_every_module():
    for path in LIBRARY_MODULES:
        importlib.import_module(_module_name(path))
