"""The subcommands of ``juno``, one module each, all defined the same way.

A command module has:

- ``HELP``: one line for ``juno --help``;
- ``OUTPUTS``: the options it writes besides ``--json``, by argument name, with the kind of
  output (``"file"``, ``"report"``, ``"plots"``, ``"campaign"``), which :mod:`juno.cli` checks
  against the command's inputs before anything runs (:mod:`juno.outputs`);
- ``add_arguments(parser)``: its own options (the common ones come from :mod:`.options`);
- ``run(args) -> int``: the command, a thin layer over the library (it parses, calls, prints).

The library never imports this package.
"""

from . import bench, diagnose, identify, report, simulate, sweep, synthesize, validate

#: The subcommands in the order ``juno --help`` lists them.
COMMANDS = {"simulate": simulate, "identify": identify, "validate": validate, "synthesize": synthesize,
            "report": report, "sweep": sweep, "diagnose": diagnose, "bench": bench}
