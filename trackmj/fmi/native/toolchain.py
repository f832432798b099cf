"""C toolchains for the native FMU: the host's C compiler for Linux x86-64 and MinGW-w64 for
Windows x86-64, each with the MuJoCo C library it links against and bundles.

The FMU's binary finds the bundled MuJoCo library in its own folder, whatever the importer's
working directory or search path:

- Linux: the binary links MuJoCo's versioned soname (libmujoco.so.<version>) with the run
  path $ORIGIN, the binary's own folder.
- Windows resolves a DLL's imports from the host executable's folder, the system folders,
  the working directory and PATH, never from the importing DLL's folder, even when the host
  loads that DLL by its full path with plain LoadLibrary (Microsoft, "Dynamic-link library
  search order"; Wine behaves the same). So mujoco.dll is delay-loaded: a hook compiled
  into the binary loads it on the first MuJoCo call from the binary's own folder by full
  path. MuJoCo's exported variables (mju_user_error, mjcb_*, ...) cannot be delay-loaded:
  the Windows build fails if the sources use them (mju_setLogHandler replaces the error
  hooks). trackmj_mujoco_load_error() lets the sources report a mujoco.dll that cannot be
  loaded instead of the delay-load exception that would end the host process.

MuJoCo's library comes from the installed `mujoco` package for Linux and from the
`mujoco-core` win_amd64 wheel of the same version for Windows (downloaded once with pip
into the user cache).
"""

from __future__ import annotations

import os
import platform
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import mujoco

CFLAGS = ("-O2", "-std=c99", "-ffp-contract=off", "-fno-fast-math", "-s")
MINGW_GCC = "x86_64-w64-mingw32-gcc"
WHEEL_ENV = "TRACKMJ_MUJOCO_WIN64_WHEEL"


@dataclass(frozen=True)
class Platform:
    """Where an FMU keeps one platform's binary and which MuJoCo library goes with it."""

    fmi2: str  # folder under binaries/ in an FMI 2.0 FMU
    fmi3: str  # platform tuple, folder under binaries/ in an FMI 3.0 FMU
    suffix: str  # shared-library file suffix
    mujoco_library: str  # file name of the bundled MuJoCo library; {version} is MuJoCo's

    def mujoco_file(self, version: str) -> str:
        """The bundled MuJoCo library's file name for MuJoCo `version`."""
        return self.mujoco_library.format(version=version)


LINUX64 = Platform("linux64", "x86_64-linux", ".so", "libmujoco.so.{version}")
WIN64 = Platform("win64", "x86_64-windows", ".dll", "mujoco.dll")


@dataclass(frozen=True)
class Toolchain:
    """A compiler that builds `platform`'s binary against MuJoCo `version`."""

    platform: Platform
    compiler: str  # path of the C compiler
    include_dir: Path  # folder holding mujoco/mujoco.h
    library: Path  # MuJoCo's shared library: linked against and copied next to the binary
    version: str  # MuJoCo's version, equal to the installed mujoco.__version__


@dataclass(frozen=True)
class Missing:
    """A platform that cannot be built here, and why (one line)."""

    platform: Platform
    reason: str


class BuildError(RuntimeError):
    """A compiler or linker failure; the message holds the command and its output."""


def linux_toolchain() -> Toolchain | Missing:
    """The host's `cc` with the installed mujoco package's libmujoco.so.<version> and headers
    (site-packages/mujoco/); Missing off Linux x86-64 or without them."""
    if not (sys.platform == "linux" and platform.machine() == "x86_64"):
        return Missing(LINUX64, f"not a Linux x86-64 host ({sys.platform} {platform.machine()})")
    compiler = shutil.which("cc")
    if compiler is None:
        return Missing(LINUX64, "no C compiler (cc) on PATH")
    version = mujoco.__version__
    package = Path(mujoco.__file__).parent
    library = package / LINUX64.mujoco_file(version)
    if not library.is_file():
        return Missing(LINUX64, f"the mujoco package has no {library.name} in {package}")
    include_dir = package / "include"
    if not (include_dir / "mujoco" / "mujoco.h").is_file():
        return Missing(LINUX64, f"the mujoco package has no headers in {include_dir}")
    return Toolchain(LINUX64, compiler, include_dir, library, version)


def win64_toolchain(cache_dir: Path | None = None) -> Toolchain | Missing:
    """MinGW-w64's x86_64-w64-mingw32-gcc with mujoco.dll and headers of the installed mujoco
    version, kept in `cache_dir`/<version>/ (default: $XDG_CACHE_HOME, else ~/.cache, then
    trackmj/mujoco-win64). They are taken from the wheel named by $TRACKMJ_MUJOCO_WIN64_WHEEL
    if set, else from the cache, else from the mujoco-core win_amd64 wheel pip downloads."""
    compiler = shutil.which(MINGW_GCC)
    if compiler is None:
        return Missing(WIN64, f"{MINGW_GCC} not found: apt-get install gcc-mingw-w64-x86-64")
    if shutil.which(_dlltool(compiler)) is None:
        return Missing(WIN64, f"{_dlltool(compiler)} not found: apt-get install "
                              "binutils-mingw-w64-x86-64")
    version = mujoco.__version__
    root = cache_dir if cache_dir is not None else _user_cache() / "trackmj" / "mujoco-win64"
    try:
        unpacked = _win64_mujoco(version, root / version)
    except (OSError, RuntimeError, zipfile.BadZipFile, subprocess.SubprocessError) as error:
        return Missing(WIN64, f"MuJoCo's win_amd64 library not available: {error}")
    return Toolchain(WIN64, compiler, unpacked / "include", unpacked / "mujoco.dll", version)


def build(toolchain: Toolchain, sources: list[Path], include_dirs: list[Path], out_dir: Path,
          name: str) -> Path:
    """Compile `sources` into out_dir/`name`.so (Linux) or .dll (Windows), linked against
    MuJoCo, and copy MuJoCo's library next to it; returns the binary's path. Raises
    BuildError with the compiler's output if the build fails."""
    out_dir.mkdir(parents=True, exist_ok=True)
    binary = out_dir / f"{name}{toolchain.platform.suffix}"
    includes = [f"-I{d}" for d in [*include_dirs, toolchain.include_dir]]
    common = [toolchain.compiler, *CFLAGS, "-shared", *includes, *map(str, sources)]
    variables: list[str] = []
    with tempfile.TemporaryDirectory(prefix="trackmj-build-") as tmp:
        if toolchain.platform == WIN64:
            functions, variables = _pe_exports(toolchain.library)
            delaylib = _delay_import_library(toolchain, functions, Path(tmp))
            hook = Path(tmp) / "trackmj_mujoco_loader.c"
            hook.write_text(_WIN64_LOADER_C)
            command = [*common, str(hook), "-static-libgcc", "-o", str(binary), str(delaylib)]
        else:
            command = [*common, "-fPIC", "-fvisibility=hidden", "-o", str(binary),
                       str(toolchain.library), "-Wl,-rpath,$ORIGIN", "-Wl,-z,defs", "-lm"]
        try:
            _run(command, f"{toolchain.platform.fmi2} build of {name}")
        except BuildError as error:
            used = [v for v in variables if f"__imp_{v}'" in str(error)]
            if used:
                raise BuildError(f"{error}\nmujoco.dll is delay-loaded, so the Windows build "
                                 f"cannot use MuJoCo's variables ({', '.join(used)})") from None
            raise
    bundled = out_dir / toolchain.library.name
    if bundled.resolve() != toolchain.library.resolve():
        shutil.copyfile(toolchain.library, bundled)
    return binary


def imported_libraries(path: Path) -> list[str]:
    """The shared libraries a built binary imports at load time, as its file records them
    (ELF NEEDED sonames or PE import-table "DLL Name"s, in order), read with binutils'
    objdump. A Windows binary's delay-loaded mujoco.dll is not among them: GNU ld leaves the
    PE delay-import directory empty."""
    objdump = shutil.which("objdump") or shutil.which("x86_64-w64-mingw32-objdump")
    if objdump is None:
        raise BuildError("objdump not found: apt-get install binutils")
    dump = _run([objdump, "-p", str(path)], f"objdump of {path.name}")
    return re.findall(r"^\s*(?:NEEDED|DLL Name:)\s+(\S+)\s*$", dump, re.MULTILINE)


# The delay-load hook of the Windows binary (see the module's docstring).
_WIN64_LOADER_C = r"""/* Generated by trackmj.fmi.native.toolchain: mujoco.dll is delay-loaded from
   this DLL's own folder, since Windows looks for a DLL's imports next to the host program. */
#include <windows.h>
#include <delayimp.h>
#include <stdio.h>
#include <wchar.h>

static HMODULE mujoco_module;
static char load_error[1024];

static void load_mujoco(void) {
    static wchar_t path[32768];
    HMODULE self;
    if (mujoco_module || load_error[0]) return;
    if (!GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS
                            | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCWSTR)(void *)&load_mujoco, &self)) {
        snprintf(load_error, sizeof load_error, "cannot find the FMU's own DLL: error %lu",
                 GetLastError());
        return;
    }
    DWORD n = GetModuleFileNameW(self, path, 32768 - 16);
    wchar_t *slash = n ? wcsrchr(path, L'\\') : NULL;
    if (!slash) {
        snprintf(load_error, sizeof load_error, "cannot find the FMU's own folder");
        return;
    }
    wcscpy(slash + 1, L"mujoco.dll");
    mujoco_module = LoadLibraryExW(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    if (!mujoco_module)
        snprintf(load_error, sizeof load_error, "cannot load %ls: Windows error %lu (mujoco.dll "
                 "needs the Microsoft Visual C++ 2015-2022 runtime, MSVCP140.dll)", path,
                 GetLastError());
}

/* NULL once mujoco.dll is loaded, else why it cannot be (one line). */
const char *trackmj_mujoco_load_error(void) {
    load_mujoco();
    return load_error[0] ? load_error : NULL;
}

static FARPROC WINAPI delay_hook(unsigned notify, PDelayLoadInfo info) {
    if (notify != dliNotePreLoadLibrary || _stricmp(info->szDll, "mujoco.dll") != 0)
        return NULL;
    load_mujoco();
    return (FARPROC)mujoco_module;
}

PfnDliHook __pfnDliNotifyHook2 = delay_hook;
"""


def _run(command: list[str], what: str) -> str:
    """Run `command`; its stdout, or BuildError naming `what` with the command's output."""
    run = subprocess.run(command, capture_output=True, text=True)
    if run.returncode != 0:
        raise BuildError(f"{what} failed (exit {run.returncode}): {' '.join(command)}\n"
                         f"{run.stderr}{run.stdout}")
    return run.stdout


def _dlltool(compiler: str) -> str:
    """The MinGW dlltool next to MinGW's gcc."""
    return re.sub(r"gcc(\.exe)?$", r"dlltool\1", compiler)


def _user_cache() -> Path:
    """$XDG_CACHE_HOME, else ~/.cache."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")


def _win64_mujoco(version: str, cached: Path) -> Path:
    """`cached`, holding mujoco.dll and include/mujoco/*.h of MuJoCo `version`, unpacked there
    first if needed from $TRACKMJ_MUJOCO_WIN64_WHEEL or a wheel pip downloads."""
    wheel = os.environ.get(WHEEL_ENV)
    if wheel:
        _unpack(Path(wheel), version, cached, f"${WHEEL_ENV}={wheel}")
    elif not (cached / "mujoco.dll").is_file():
        with tempfile.TemporaryDirectory(prefix="trackmj-wheel-") as tmp:
            python = f"{sys.version_info.major}.{sys.version_info.minor}"
            command = [sys.executable, "-m", "pip", "download", f"mujoco-core=={version}",
                       "--platform", "win_amd64", "--python-version", python,
                       "--only-binary=:all:", "--no-deps", "--disable-pip-version-check",
                       "--quiet", "-d", tmp]
            run = subprocess.run(command, capture_output=True, text=True, timeout=600)
            wheels = sorted(Path(tmp).glob("*.whl"))
            if run.returncode != 0 or not wheels:
                last = (run.stderr.strip().splitlines() or ["no wheel"])[-1]
                raise RuntimeError(f"pip download mujoco-core=={version} failed: {last}")
            _unpack(wheels[0], version, cached, wheels[0].name)
    return cached


def _unpack(wheel: Path, version: str, cached: Path, source: str) -> None:
    """Extract mujoco.dll and the headers of the mujoco-core win_amd64 `wheel` (of MuJoCo
    `version`, else RuntimeError naming `source`) into `cached`, unless already there.
    Atomic: extracted into a sibling temporary folder, then renamed."""
    if (cached / "mujoco.dll").is_file():
        return
    match = re.fullmatch(r"mujoco_core-([^-]+)-.*-win_amd64\.whl", wheel.name)
    if match is None or match.group(1) != version:
        raise RuntimeError(f"{source} is not the mujoco-core {version} win_amd64 wheel")
    cached.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{cached.name}-", dir=cached.parent))
    try:
        with zipfile.ZipFile(wheel) as zf:
            for member in zf.namelist():
                inner = member.removeprefix("mujoco/")
                if inner == "mujoco.dll" or inner.startswith("include/mujoco/"):
                    target = staging / inner
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(zf.read(member))
        if not (staging / "mujoco.dll").is_file():
            raise RuntimeError(f"{source} has no mujoco/mujoco.dll")
        staging.chmod(0o755)  # mkdtemp's folder is private
        try:
            staging.rename(cached)
        except OSError:
            if not (cached / "mujoco.dll").is_file():  # not another process's finished copy
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _pe_exports(dll: Path) -> tuple[list[str], list[str]]:
    """(functions, variables): the names a PE32+ DLL exports, split by whether the exported
    address lies in an executable section."""
    data = dll.read_bytes()
    pe = struct.unpack_from("<I", data, 0x3C)[0]
    if data[pe:pe + 4] != b"PE\0\0":
        raise BuildError(f"{dll} is not a PE file")
    n_sections, optional_size = struct.unpack_from("<2xH12xH", data, pe + 4)
    optional = pe + 24
    if struct.unpack_from("<H", data, optional)[0] != 0x20B:
        raise BuildError(f"{dll} is not a 64-bit (PE32+) DLL")
    export_rva = struct.unpack_from("<I", data, optional + 112)[0]
    sections = []
    for k in range(n_sections):
        header = optional + optional_size + 40 * k
        size, rva, raw_size, raw = struct.unpack_from("<4I", data, header + 8)
        flags = struct.unpack_from("<I", data, header + 36)[0]
        sections.append((rva, max(size, raw_size), raw, bool(flags & 0x20000000)))

    def section(rva: int) -> tuple[int, bool]:
        """(file offset of `rva`, whether its section is executable)."""
        for start, size, raw, executable in sections:
            if start <= rva < start + size:
                return rva - start + raw, executable
        raise BuildError(f"{dll}: address {rva:#x} is in no section")

    directory = section(export_rva)[0]
    _, n_names, functions_rva, names_rva, ordinals_rva = struct.unpack_from(
        "<5I", data, directory + 20)
    functions, variables = [], []
    for k in range(n_names):
        name_at = section(struct.unpack_from("<I", data, section(names_rva)[0] + 4 * k)[0])[0]
        name = data[name_at:data.index(b"\0", name_at)].decode("ascii")
        ordinal = struct.unpack_from("<H", data, section(ordinals_rva)[0] + 2 * k)[0]
        address = struct.unpack_from("<I", data, section(functions_rva)[0] + 4 * ordinal)[0]
        (functions if section(address)[1] else variables).append(name)
    return functions, variables


def _delay_import_library(toolchain: Toolchain, functions: list[str], tmp: Path) -> Path:
    """A MinGW delay-import library of `functions` of MuJoCo's DLL, built in `tmp`."""
    definition = tmp / "mujoco.def"
    definition.write_text(f"LIBRARY {toolchain.library.name}\nEXPORTS\n"
                          + "".join(f"{name}\n" for name in functions))
    delaylib = tmp / "libmujoco_delay.a"
    _run([_dlltool(toolchain.compiler), "--input-def", str(definition), "--dllname",
          toolchain.library.name, "--output-delaylib", str(delaylib)],
         "mujoco.dll's delay-import library")
    return delaylib
