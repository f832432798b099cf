"""Running Windows x86-64 programs built with MinGW-w64 under Wine, for the tests of the
native FMU's Windows binary (Debian packages wine64 and gcc-mingw-w64-x86-64, which
.ci/run installs).

Every run of a test session shares one private Wine prefix in a temporary folder, made on
first use (its first boot takes a few seconds) and removed, with its wineserver stopped, at
exit.
"""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import tempfile
from pathlib import Path, PureWindowsPath

import pytest

MINGW_GCC = "x86_64-w64-mingw32-gcc"
# Debian's wine64 package installs its loader here only; the `wine` package adds /usr/bin/wine.
_CANDIDATES = ("wine64", "wine", "/usr/lib/wine/wine64")
_HELLO_C = '#include <stdio.h>\nint main(void) { printf("hello from wine\\n"); return 0; }\n'


def windows_path(path: Path) -> str:
    """`path` as a Windows program under Wine names it (Wine's drive Z: is the root /)."""
    return str(PureWindowsPath("Z:\\", *path.resolve().parts[1:]))


_PROBE_ATTEMPTS = 2
"""Runs of the probe per loader: the prefix's first boot (wineboot) runs under the first
program, and once in a CI run (2026-12-08) the first worker's probe did not print while the
other worker's did; a second run then finds the prefix booted."""
_probe_failures: list[str] = []
"""What each failed probe saw, for :func:`wine_missing`."""


@functools.cache
def wine_available() -> str | None:
    """The path of a Wine loader (wine64 or wine) that runs a trivial program MinGW-w64
    built, or None (no MinGW-w64, no Wine, or a Wine that cannot run it; what the probes
    saw in :func:`wine_missing`). Checked once."""
    compiler = shutil.which(MINGW_GCC)
    if compiler is None:
        _probe_failures.append(f"no {MINGW_GCC} on PATH")
        return None
    work = Path(_session_dir())
    (work / "hello.c").write_text(_HELLO_C)
    built = subprocess.run([compiler, str(work / "hello.c"), "-o", str(work / "hello.exe")],
                           capture_output=True, text=True)
    if built.returncode != 0:
        _probe_failures.append(f"{MINGW_GCC} failed: {built.stderr.strip()[-300:]}")
        return None
    for candidate in _CANDIDATES:
        wine = shutil.which(candidate)
        if wine is None:
            continue
        for _ in range(_PROBE_ATTEMPTS):
            try:
                run = _run(wine, work / "hello.exe", [], timeout=300)
            except subprocess.TimeoutExpired:
                _probe_failures.append(f"{wine}: no answer in 300 s")
                continue
            if run.returncode == 0 and run.stdout.strip() == "hello from wine":
                return wine
            _probe_failures.append(f"{wine}: exit {run.returncode}, stdout "
                                   f"{run.stdout.strip()[-200:]!r}, stderr "
                                   f"{run.stderr.strip()[-300:]!r}")
    if not _probe_failures:
        _probe_failures.append(f"none of {', '.join(_CANDIDATES)} on PATH")
    return None


def wine_missing(why: str) -> str:
    """``why`` with what the probes of :func:`wine_available` saw (call after it)."""
    return f"{why}: {'; '.join(_probe_failures)}" if _probe_failures else why


def run_under_wine(exe: Path, args: list[str], timeout: float
                   ) -> subprocess.CompletedProcess[str]:
    """Run the Windows program `exe` with `args` under Wine in the session's prefix, with no
    Wine debug output and no Unix environment but Wine's own settings; its stdout and
    stderr as text. Requires wine_available()."""
    wine = wine_available()
    if wine is None:
        raise RuntimeError("Wine cannot run MinGW-w64 programs here (see wine_available)")
    return _run(wine, exe, args, timeout)


def _run(wine: str, exe: Path, args: list[str], timeout: float
         ) -> subprocess.CompletedProcess[str]:
    """`exe` `args` run by the loader `wine` in the session's prefix."""
    env = {"WINEPREFIX": str(Path(_session_dir()) / "prefix"), "WINEDEBUG": "-all",
           # no .NET (Mono) or HTML (Gecko) engine: the first boot does not offer to fetch them
           "WINEDLLOVERRIDES": "mscoree,mshtml=", "PATH": "/usr/bin:/bin"}
    return subprocess.run([wine, str(exe), *args], capture_output=True, text=True, env=env,
                          timeout=timeout)


@functools.cache
def _session_dir() -> str:
    """A temporary folder for this process's Wine prefix and probe, removed at exit."""
    folder = tempfile.mkdtemp(prefix="trackmj-wine-")
    atexit.register(_cleanup, folder)
    return folder


def _cleanup(folder: str) -> None:
    """Stop the prefix's wineserver (it lingers after its last program) and remove `folder`."""
    prefix = Path(folder) / "prefix"
    wine = wine_available()
    if wine is not None and prefix.is_dir():
        server = Path(wine).resolve().parent / "wineserver"
        if server.is_file():
            subprocess.run([str(server), "-k"], env={"WINEPREFIX": str(prefix)},
                           capture_output=True, timeout=60)
    shutil.rmtree(folder, ignore_errors=True)


def require(available: object, why: str) -> None:
    """Skip the calling test when ``available`` is falsy, or fail it in CI (TRACKMJ_CI=1),
    where .ci/run installs MinGW-w64 and Wine."""
    if not available:
        if os.environ.get("TRACKMJ_CI") == "1":
            pytest.fail(f"{why} (CI installs it: see .ci/run)")
        pytest.skip(why)
