"""The FMU's shared library exports every FMI 2.0 Co-Simulation function and nothing else, so
it links beside other FMUs and importers without a clash of model symbols."""

from __future__ import annotations

import shutil
import subprocess
import zipfile

import pytest

FMI2_CS_FUNCTIONS = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
    "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
    "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
    "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus",
}


def test_the_linux_binary_exports_exactly_the_fmi2_functions(fmu_path, tmp_path):
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("nm (binutils) is not installed")
    with zipfile.ZipFile(fmu_path) as z:
        names = [n for n in z.namelist() if n.startswith("binaries/") and n.endswith(".so")]
        assert names == ["binaries/linux64/JunoRover.so"], names
        z.extract(names[0], tmp_path)
    out = subprocess.run([nm, "-D", "--defined-only", str(tmp_path / names[0])], capture_output=True, text=True,
                         check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.split()[1:2] and line.split()[1] in "TDBR"}
    assert exported == FMI2_CS_FUNCTIONS, (f"missing: {sorted(FMI2_CS_FUNCTIONS - exported)}; "
                                           f"leaked: {sorted(exported - FMI2_CS_FUNCTIONS)}")


def test_the_linux_binary_loads_on_glibc_2_17(fmu_path, tmp_path):
    """No symbol of the FMU needs a glibc newer than 2.17 (fmu_src/glibc_compat.h), so it loads on
    Debian 8, Ubuntu 14.04, RHEL 7 and later, not only where it was built."""
    objdump = shutil.which("objdump")
    if objdump is None:
        pytest.skip("objdump (binutils) is not installed")
    with zipfile.ZipFile(fmu_path) as z:
        z.extract("binaries/linux64/JunoRover.so", tmp_path)
    out = subprocess.run([objdump, "-T", str(tmp_path / "binaries/linux64/JunoRover.so")], capture_output=True,
                         text=True, check=True).stdout
    needed = {}
    for line in out.splitlines():
        if "GLIBC_" in line:
            version = line.split("GLIBC_")[1].split()[0].rstrip(")")
            needed[line.split()[-1]] = tuple(int(x) for x in version.split("."))
    assert needed, "no glibc symbols found: the check reads nothing"
    too_new = {name: ".".join(map(str, v)) for name, v in needed.items() if v > (2, 17)}
    assert not too_new, f"symbols needing a glibc newer than 2.17: {too_new}"


@pytest.mark.parametrize("processor, folder", [("aarch64", "aarch64-linux"), ("x86_64", "linux64"),
                                               ("riscv64", None)])
def test_the_binaries_folder_names_the_processor(processor, folder, tmp_path):
    """Configured for another processor, the FMU's binaries go to that processor's folder (FMI
    2.0.4 names for ARM), and a processor without one is refused at configure time."""
    from pathlib import Path
    cmake = shutil.which("cmake")
    if cmake is None:
        pytest.skip("cmake is not installed")
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([cmake, "-S", str(root), "-B", str(tmp_path / "b"), "-G", "Ninja",
                           "-DCMAKE_SYSTEM_NAME=Linux", f"-DCMAKE_SYSTEM_PROCESSOR={processor}"],
                          capture_output=True, text=True, timeout=300)
    if folder is None:
        assert proc.returncode != 0 and f"processor '{processor}'" in proc.stderr
    else:
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert f"binaries/{folder}" in (tmp_path / "b" / "build.ninja").read_text()
