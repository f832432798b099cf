"""The native FMU's toolchains (trackmj/fmi/native/toolchain.py): a small C library calling
MuJoCo, built for Linux x86-64 and cross-built for Windows x86-64, answers MuJoCo's version
from a C host that loads it by its full path from another folder, with the MuJoCo library
bundled next to it as the only non-system library; the Windows build runs under Wine.

Without MinGW-w64 or Wine these tests skip, except in CI (.ci/run sets TRACKMJ_CI=1 and
installs both), where a missing tool is a failure."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import mujoco
import pytest
from wine import require, run_under_wine, windows_path, wine_available, wine_missing

from trackmj.fmi.native import toolchain

PROBE_C = r"""#include <mujoco/mujoco.h>
#ifdef _WIN32
#define EXPORT __declspec(dllexport)
const char *trackmj_mujoco_load_error(void);
#else
#define EXPORT __attribute__((visibility("default")))
#endif
/* MuJoCo's version string. */
EXPORT const char *probe_version(void) { return mj_versionString(); }
#ifdef _WIN32
/* Why mujoco.dll cannot be loaded, or "loaded". */
EXPORT const char *probe_load_error(void) {
    const char *error = trackmj_mujoco_load_error();
    return error ? error : "loaded";
}
#endif
"""

HOST_C = r"""#include <stdio.h>
#ifdef _WIN32
#include <windows.h>
#define OPEN(path) LoadLibraryA(path)
#define SYMBOL(lib, name) (void *)GetProcAddress(lib, name)
#else
#include <dlfcn.h>
#define OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#endif
/* usage: host LIBRARY [FUNCTION]: load LIBRARY by its path, print what FUNCTION
   (probe_version by default) returns. */
int main(int argc, char **argv) {
    if (argc != 2 && argc != 3) return 2;
    void *lib = (void *)OPEN(argv[1]);
    if (!lib) {
#ifdef _WIN32
        fprintf(stderr, "LoadLibraryA: error %lu\n", GetLastError());
#else
        fprintf(stderr, "dlopen: %s\n", dlerror());
#endif
        return 2;
    }
    const char *name = argc == 3 ? argv[2] : "probe_version";
    const char *(*probe)(void) = (const char *(*)(void))SYMBOL(lib, name);
    if (!probe) return 2;
    printf("%s\n", probe());
    return 0;
}
"""

# Libraries of Windows itself and of its C runtimes (Universal CRT, msvcrt): all a built DLL
# may import besides MuJoCo's bundled one.
WINDOWS_SYSTEM = {"kernel32.dll", "msvcrt.dll", "user32.dll", "advapi32.dll", "ntdll.dll",
                  "ucrtbase.dll"}


def _system_dll(name: str) -> bool:
    return name.lower() in WINDOWS_SYSTEM or name.lower().startswith("api-ms-win-")


@pytest.fixture(scope="module")
def linux() -> toolchain.Toolchain:
    found = toolchain.linux_toolchain()
    require(not isinstance(found, toolchain.Missing), getattr(found, "reason", ""))
    assert isinstance(found, toolchain.Toolchain)
    return found


@pytest.fixture(scope="module")
def win64() -> toolchain.Toolchain:
    """The Windows toolchain, with mujoco.dll from the user cache (downloaded once)."""
    found = toolchain.win64_toolchain()
    require(not isinstance(found, toolchain.Missing), getattr(found, "reason", ""))
    assert isinstance(found, toolchain.Toolchain)
    return found


def _probe(tc: toolchain.Toolchain, folder: Path) -> Path:
    """PROBE_C built by `tc` into `folder`/probe (.so or .dll); its path."""
    source = folder.parent / "probe.c"
    source.write_text(PROBE_C)
    return toolchain.build(tc, [source], [], folder, "probe")


def test_a_linux_build_finds_its_bundled_mujoco_from_any_folder(linux, tmp_path) -> None:
    """Built, then moved: a C host (empty environment, another working folder) loads it and
    reads the installed mujoco's version; without the bundled copy it cannot load."""
    _probe(linux, tmp_path / "build")
    moved = tmp_path / "moved"
    shutil.move(tmp_path / "build", moved)
    host = tmp_path / "host"
    (tmp_path / "host.c").write_text(HOST_C)
    subprocess.run(["cc", str(tmp_path / "host.c"), "-o", str(host), "-ldl"], check=True)
    run = subprocess.run([str(host), str(moved / "probe.so")], capture_output=True, text=True,
                         env={}, cwd=tmp_path, timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == mujoco.__version__
    imports = toolchain.imported_libraries(moved / "probe.so")
    assert f"libmujoco.so.{mujoco.__version__}" in imports
    assert not [lib for lib in imports if "python" in lib.lower()], imports
    (moved / f"libmujoco.so.{mujoco.__version__}").unlink()
    run = subprocess.run([str(host), str(moved / "probe.so")], capture_output=True, text=True,
                         env={}, cwd=tmp_path, timeout=60)
    assert run.returncode == 2 and f"libmujoco.so.{mujoco.__version__}" in run.stderr


def test_a_compiler_error_is_raised_with_the_compilers_message(linux, tmp_path) -> None:
    broken = tmp_path / "broken.c"
    broken.write_text("int f(void) { return undeclared_name; }\n")
    with pytest.raises(toolchain.BuildError, match="undeclared_name"):
        toolchain.build(linux, [broken], [], tmp_path / "out", "broken")


def test_a_win64_build_under_wine_loads_mujoco_dll_from_its_own_folder(win64,
                                                                       tmp_path) -> None:
    """A plain LoadLibraryA host in another folder (Windows would look for a static import
    next to the host, not the DLL): the DLL's first MuJoCo call answers MuJoCo's version,
    it imports only Windows system DLLs (mujoco.dll is delay-loaded from its folder) and,
    without mujoco.dll, trackmj_mujoco_load_error says why."""
    require(wine_available(), wine_missing("Wine cannot run MinGW-w64 programs here"))
    dll = _probe(win64, tmp_path / "fmu")
    assert all(map(_system_dll, toolchain.imported_libraries(dll))), \
        toolchain.imported_libraries(dll)
    host = tmp_path / "host" / "host.exe"
    host.parent.mkdir()
    (tmp_path / "host.c").write_text(HOST_C)
    subprocess.run([win64.compiler, str(tmp_path / "host.c"), "-o", str(host)], check=True)
    run = run_under_wine(host, [windows_path(dll)], timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == mujoco.__version__
    (tmp_path / "fmu" / "mujoco.dll").unlink()
    run = run_under_wine(host, [windows_path(dll), "probe_load_error"], timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("cannot load") and "mujoco.dll" in run.stdout


def test_the_bundled_mujoco_dll_needs_only_windows_and_the_msvc_runtime(win64) -> None:
    """What the FMU's user needs besides the FMU: Windows and Microsoft's Visual C++ runtime
    (MSVCP140.dll, VCRUNTIME140*.dll), which mujoco.dll imports."""
    imports = toolchain.imported_libraries(win64.library)
    others = [d for d in imports if not _system_dll(d)]
    assert others and all(d.lower().startswith(("msvcp140", "vcruntime140")) for d in others)


def test_a_win64_build_using_mujocos_variables_is_refused_naming_them(win64,
                                                                       tmp_path) -> None:
    source = tmp_path / "handler.c"
    source.write_text('#include <mujoco/mujoco.h>\nstatic void on_error(const char *m) '
                      '{ (void)m; }\n__declspec(dllexport) void install(void) '
                      '{ mju_user_error = on_error; }\n')
    with pytest.raises(toolchain.BuildError, match="cannot use MuJoCo's variables "
                                                   r"\(mju_user_error\)"):
        toolchain.build(win64, [source], [], tmp_path / "out", "handler")


@pytest.mark.parametrize(("wheel", "reason"), [
    ("mujoco_core-0.0.1-cp311-cp311-win_amd64.whl",
     f"is not the mujoco-core {mujoco.__version__} win_amd64 wheel"),
    (f"mujoco_core-{mujoco.__version__}-cp311-cp311-win_amd64.whl", "has no mujoco/mujoco.dll"),
])
def test_a_wrong_win64_wheel_is_missing_with_its_reason_and_caches_nothing(
        wheel, reason, tmp_path, monkeypatch) -> None:
    require(shutil.which(toolchain.MINGW_GCC), "the wheel is read only with MinGW-w64 "
            "present")
    path = tmp_path / wheel
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("mujoco/__init__.py", "")
    monkeypatch.setenv(toolchain.WHEEL_ENV, str(path))
    found = toolchain.win64_toolchain(tmp_path / "cache")
    assert isinstance(found, toolchain.Missing) and found.platform == toolchain.WIN64
    assert found.reason.startswith("MuJoCo's win_amd64 library not available: ")
    assert reason in found.reason
    assert not any((tmp_path / "cache").rglob("*"))
