"""trackmj's plant as an FMU: ``trackmj fmu export plant -o FILE.fmu`` (the track alone is
exported natively, by :mod:`trackmj.fmi.native`).

The exporter is pythonfmu (FMI 2.0 co-simulation): the FMU holds a small generated Python
module (the slave class, :class:`trackmj.fmi.slaves.PlantSlave`) and pythonfmu's FMI
binary, which embeds a Python interpreter in the importing tool and runs the module there.
So the importing machine needs:

* Linux x86-64 and the same Python (major.minor) as the exporting one, as a shared library
  (libpython), with trackmj and its dependencies installed; the module adds the exporting
  environment's site-packages (recorded at export) to ``sys.path``, so an FMU exported from
  a virtual environment runs from that environment on the same machine; elsewhere install
  trackmj into the host's Python;
* nothing else. The FMU's binary is a small C layer compiled here with the system C
  compiler (``cc``; the export needs it) over pythonfmu's binary:

  - it depends on libpython (by its full path) and on pythonfmu's binary and makes
    libpython's symbols global, so that a tool that is not Python (Simulink, AMESim, a C
    program) loads it and Python's extension modules load in it (pythonfmu's binary does
    not name libpython as a dependency: its open issue 202);
  - it gives the FMU FMI's error contract: pythonfmu 0.7 turns every Python exception into
    fmi2Fatal and releases the slave, and a failed doStep into fmi2Discard; the slave
    raises nothing and logs an error-level message instead, and a call during which it
    logged one returns fmi2Error (the instance stays usable: restore a state or reset);
  - it passes error and warning messages to the host's logger whether or not the host
    turned debug logging on (pythonfmu forwards none without), other messages as the host
    asked (fmi2SetDebugLogging).

The generated module also puts the exporting environment's site-packages ahead of the host
Python's own (measured: the host's older scipy shadowing the environment's crashed the
embedded interpreter), sets ``sys.executable`` where the host has none (mujoco's glfw probe
starts a subprocess), holds a reference pythonfmu releases once too often
(:func:`hold_module_dict`), and freezes the garbage collector at interpreter
exit: in a C host the final cycle collection of ``Py_Finalize`` (pythonfmu finalises the
interpreter it started when the FMU is unloaded) crashed on a corrupted object with MuJoCo,
numba and scipy loaded; the root cause was not found, the process ending frees the memory.

The modelDescription pythonfmu writes is completed here from :data:`trackmj.fmi.slaves.
SIGNALS`: SI units (UnitDefinitions), the inputs' and parameters' ranges, the outputs'
dependencies (none: outputs change only in doStep), InitialUnknowns, author, version,
licence and generation tool.

Limits: several instances per process are fine (each is its own Python object in the one
interpreter); the GIL serialises them. Only FMI 2.0 and only 64-bit Linux binaries.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

from trackmj.version import __version__

KINDS = {"plant": ("TrackmjPlant", "PlantSlave")}
"""Export kind -> (model identifier, slave class in :mod:`trackmj.fmi.slaves`)."""
PYTHONFMU_BINARY = "libpythonfmu-export.so"
"""pythonfmu's FMI binary under its own name (its soname), beside the shim."""
AUTHOR = "trackmj maintainers"
LICENSE = "Apache-2.0"
UNITS: dict[str, dict[str, int]] = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "Pa": {"kg": 1, "m": -1, "s": -2},
}
"""FMI unit name -> SI base-unit exponents (the BaseUnit attributes of UnitDefinitions)."""

SHIM_C = r"""
/* trackmj's FMU binary: a layer over pythonfmu's FMI binary (a dependency of this library,
   as libpython is; the importer finds the fmi2* functions this file does not define in
   pythonfmu's). It makes libpython's symbols global (Python's extension modules then load
   in a host without Python), returns fmi2Error from a call during which the Python slave
   logged an error-level message (pythonfmu 0.7 has no other way for a slave to fail a call
   without fmi2Fatal), and passes warnings and errors to the host's logger even with debug
   logging off. The FMI 2.0 types are declared here (their ABI is the standard's). */
#include <dlfcn.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef char fmi2Byte;
typedef int fmi2Status;
enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal };
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status,
                                   fmi2String, fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef struct Instance {
    struct Instance *next;
    fmi2Component inner;            /* pythonfmu's instance, the importer's handle */
    fmi2CallbackFunctions own;      /* given to pythonfmu: this layer's logger */
    fmi2CallbackLogger host_logger;
    fmi2ComponentEnvironment host_env;
    int logging;                    /* the host's debug logging switch */
    size_t n_categories;            /* the host's categories (0: all) */
    char **categories;
    int errors;                     /* error-level messages logged in the current call */
} Instance;

static Instance *instances;
static pthread_mutex_t instances_lock = PTHREAD_MUTEX_INITIALIZER;
static void *pythonfmu;

__attribute__((constructor)) static void trackmj_load(void) {
    dlopen(LIBPYTHON, RTLD_NOW | RTLD_NOLOAD | RTLD_GLOBAL);
    pythonfmu = dlopen(PYTHONFMU, RTLD_NOW | RTLD_NOLOAD);
}

static void *inner(const char *name) { return pythonfmu ? dlsym(pythonfmu, name) : NULL; }

static Instance *find(fmi2Component c) {
    pthread_mutex_lock(&instances_lock);
    Instance *i = instances;
    while (i && i->inner != c) i = i->next;
    pthread_mutex_unlock(&instances_lock);
    return i;
}

static void free_categories(Instance *i) {
    for (size_t k = 0; k < i->n_categories; k++) free(i->categories[k]);
    free(i->categories);
    i->categories = NULL;
    i->n_categories = 0;
}

static int wanted(const Instance *i, fmi2Status status, fmi2String category) {
    if (status >= fmi2Warning) return 1;
    if (!i->logging) return 0;
    for (size_t k = 0; k < i->n_categories; k++)
        if (category && strcmp(i->categories[k], category) == 0) return 1;
    return i->n_categories == 0;
}

/* pythonfmu passes the text as the format, without arguments; it goes on so, its '%'
   doubled: a host that formats the message (as FMI asks) and one that prints it as it is
   both show the text. */
static void log_message(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                        fmi2String category, fmi2String message, ...) {
    Instance *i = env;
    if (status >= fmi2Error) i->errors++;
    if (!i->host_logger || !wanted(i, status, category)) return;
    size_t n = message ? strlen(message) : 0, percents = 0;
    for (size_t k = 0; k < n; k++) percents += message[k] == '%';
    char *format = malloc(n + percents + 1);
    if (!format) return;
    char *out = format;
    for (size_t k = 0; k < n; k++)
        if ((*out++ = message[k]) == '%') *out++ = '%';
    *out = '\0';
    i->host_logger(i->host_env, name, status, category, format);
    free(format);
}

fmi2Component fmi2Instantiate(fmi2String name, int type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    typedef fmi2Component (*F)(fmi2String, int, fmi2String, fmi2String,
                               const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
    F f = (F)inner("fmi2Instantiate");
    Instance *i = calloc(1, sizeof *i);
    if (!f || !i) {
        free(i);
        return NULL;
    }
    if (functions) {
        i->own = *functions;
        i->host_logger = functions->logger;
        i->host_env = functions->componentEnvironment;
    }
    i->own.logger = log_message;
    i->own.componentEnvironment = i;
    i->logging = loggingOn;
    i->inner = f(name, type, guid, resources, &i->own, visible, 1);
    if (!i->inner) {
        free(i);
        return NULL;
    }
    pthread_mutex_lock(&instances_lock);
    i->next = instances;
    instances = i;
    pthread_mutex_unlock(&instances_lock);
    return i->inner;
}

void fmi2FreeInstance(fmi2Component c) {
    void (*f)(fmi2Component) = (void (*)(fmi2Component))inner("fmi2FreeInstance");
    if (f) f(c);
    pthread_mutex_lock(&instances_lock);
    Instance **at = &instances;
    while (*at && (*at)->inner != c) at = &(*at)->next;
    Instance *i = *at;
    if (i) *at = i->next;
    pthread_mutex_unlock(&instances_lock);
    if (i) {
        free_categories(i);
        free(i);
    }
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n,
                               const fmi2String categories[]) {
    Instance *i = find(c);
    if (!i) return fmi2Error;
    free_categories(i);
    i->logging = loggingOn;
    i->categories = n ? calloc(n, sizeof(char *)) : NULL;
    for (size_t k = 0; i->categories && k < n; k++)
        if ((i->categories[k] = strdup(categories[k]))) i->n_categories++;
    return fmi2OK;
}

#define CALL(name, params, args)                                           \
    fmi2Status name params {                                               \
        typedef fmi2Status(*F) params;                                     \
        F f = (F)inner(#name);                                             \
        Instance *i = find(c);                                             \
        if (!f || !i) return fmi2Error;                                    \
        i->errors = 0;                                                     \
        fmi2Status status = f args;                                        \
        return status < fmi2Error && i->errors ? fmi2Error : status;       \
    }

CALL(fmi2SetupExperiment, (fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
     fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime),
     (c, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime))
CALL(fmi2EnterInitializationMode, (fmi2Component c), (c))
CALL(fmi2ExitInitializationMode, (fmi2Component c), (c))
CALL(fmi2Terminate, (fmi2Component c), (c))
CALL(fmi2Reset, (fmi2Component c), (c))
CALL(fmi2GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]),
     (c, vr, n, v))
CALL(fmi2GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     fmi2Integer v[]), (c, vr, n, v))
CALL(fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     fmi2Boolean v[]), (c, vr, n, v))
CALL(fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     fmi2String v[]), (c, vr, n, v))
CALL(fmi2SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2Real v[]), (c, vr, n, v))
CALL(fmi2SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2Integer v[]), (c, vr, n, v))
CALL(fmi2SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2Boolean v[]), (c, vr, n, v))
CALL(fmi2SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2String v[]), (c, vr, n, v))
CALL(fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
CALL(fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s))
CALL(fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
CALL(fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *size),
     (c, s, size))
CALL(fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size),
     (c, s, b, size))
CALL(fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t size,
     fmi2FMUstate *s), (c, b, size, s))
CALL(fmi2DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior),
     (c, t, h, noSetPrior))
"""


@dataclass(frozen=True)
class Exported:
    """What an export made: the FMU ``path``, its model ``identifier`` and the lines to tell
    the user."""

    path: Path
    identifier: str
    notes: tuple[str, ...]

_HELD: list[dict] = []


def hold_module_dict(namespace: dict) -> None:
    """Keep one more reference to a pythonfmu slave module's globals, each time the module's
    code runs. pythonfmu 0.7's binary (``findClass``, PySlaveInstance.cpp) executes the
    module's file in the module's dict and then DECREFs that dict, which
    ``PyModule_GetDict`` lent it (a borrowed reference): one reference too few per
    instantiation, and the dict is freed while in use (measured: segmentation faults in the
    garbage collector, at random, in fmpy and in a C host). Call it at the top level of
    every pythonfmu slave script (this module imports only the standard library and
    trackmj's version, so it comes first): ``hold_module_dict(globals())``."""
    _HELD.append(namespace)


def _script(identifier: str, slave: str, site_dirs: list[str]) -> str:
    version = sys.version_info[:2]
    executable = sys.executable
    return f'''"""trackmj {slave} as an FMU (generated by 'trackmj fmu export')."""
import atexit
import gc
import site
import sys

_SITE = {site_dirs!r}
if sys.version_info[:2] != {version!r}:
    raise ImportError("this FMU was exported from Python {version[0]}.{version[1]} with "
                      "trackmj; the host runs Python %d.%d" % sys.version_info[:2])
_before = list(sys.path)
for _path in _SITE:
    site.addsitedir(_path)
# the exporting environment first (after the FMU's resources): a host Python's own
# site-packages must not shadow its packages with other versions of them
_added = [p for p in sys.path if p not in _before or p in _SITE]
sys.path[:] = _before[:1] + _added + [p for p in _before[1:] if p not in _added]
if not sys.executable:   # embedded in a host without Python: subprocesses need a Python
    sys.executable = {executable!r}

from trackmj.fmi.export import hold_module_dict  # noqa: E402

hold_module_dict(globals())   # pythonfmu's findClass releases this dict once too often
atexit.register(gc.freeze)   # see trackmj.fmi.export: no cycle collection at finalisation

from pythonfmu.default_experiment import DefaultExperiment  # noqa: E402

from trackmj.fmi.slaves import {slave}  # noqa: E402


class {identifier}({slave}):
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0, step_size=1e-3)
'''


def _libpython() -> tuple[str, str] | None:
    """(soname, directory) of this Python's shared library, or None (a static Python)."""
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY")
    return name, sysconfig.get_config_var("LIBDIR")


def _build_shim(work: Path, identifier: str, pythonfmu_binary: Path) -> Path:
    """The FMU's binary (see the module docstring) over ``pythonfmu_binary``; ValueError
    naming what is missing (Linux, a shared libpython, a C compiler) or the compiler's
    message."""
    lib = _libpython()
    cc = shutil.which("cc") or shutil.which("gcc")
    if not sys.platform.startswith("linux"):
        raise ValueError(f"the plant FMU is built on Linux only (this is {sys.platform})")
    if lib is None:
        raise ValueError("the plant FMU needs a Python built with a shared libpython "
                         "(--enable-shared); this one is static")
    if cc is None:
        raise ValueError("the plant FMU's binary is compiled with the system C compiler: "
                         "no cc or gcc on PATH")
    soname, libdir = lib
    source = work / "shim.c"
    source.write_text(SHIM_C)
    out = work / f"{identifier}.so"
    link = work / PYTHONFMU_BINARY
    shutil.copy(pythonfmu_binary, link)
    result = subprocess.run(
        [cc, "-shared", "-fPIC", "-O2", "-Wall", f'-DLIBPYTHON="{soname}"',
         f'-DPYTHONFMU="{PYTHONFMU_BINARY}"', str(source), "-o", str(out),
         "-Wl,--no-as-needed", f"-L{libdir}", f"-l:{soname}", str(link),
         "-Wl,-rpath,$ORIGIN", f"-Wl,-rpath,{libdir}", "-ldl", "-lpthread"],
        capture_output=True, text=True)
    if result.returncode != 0:
        raise ValueError(f"compiling the plant FMU's binary failed: {result.stderr.strip()}")
    return out


def _describe(xml: bytes) -> bytes:
    """pythonfmu's modelDescription completed from :data:`trackmj.fmi.slaves.SIGNALS`: a
    unit on every Real (UnitDefinitions with SI base-unit exponents), min/max where a setter
    refuses values outside them, ``Outputs`` without dependencies (outputs change only in
    doStep, so none depends on an input at the same communication point),
    ``InitialUnknowns`` (the outputs; their dependencies left out: FMI 2.0 then assumes all
    knowns, a superset of the parameters they follow), which pythonfmu 0.7 leaves out and
    FMI 2.0 requires, and author, version, licence and generation tool."""
    from trackmj.fmi.slaves import SIGNALS  # local: imports MuJoCo and the plant (slow)

    root = ET.fromstring(xml)
    major, minor = __version__.split(".")[:2]
    root.attrib.update(author=AUTHOR, version=__version__, license=LICENSE,
                       generationTool=f"trackmj {major}.{minor}")
    signals = {s.name: s for s in SIGNALS}
    units: list[str] = []
    for variable in root.iter("ScalarVariable"):
        signal, typed = signals[variable.attrib["name"]], variable[0]
        if signal.unit is not None:
            typed.set("unit", signal.unit)
            units += [] if signal.unit in units else [signal.unit]
        for key, bound in (("min", signal.minimum), ("max", signal.maximum)):
            if bound is not None:
                typed.set(key, f"{bound:.16g}")
    definitions = ET.Element("UnitDefinitions")
    for unit in units:
        ET.SubElement(ET.SubElement(definitions, "Unit", name=unit), "BaseUnit",
                      {k: str(v) for k, v in UNITS[unit].items()})
    cosimulation = root.find("CoSimulation")
    if cosimulation is None:
        raise ValueError("pythonfmu's modelDescription has no CoSimulation")
    root.insert(list(root).index(cosimulation) + 1, definitions)
    structure, outputs = root.find("ModelStructure"), root.find("ModelStructure/Outputs")
    if structure is None or outputs is None or structure.find("InitialUnknowns") is not None:
        raise ValueError("pythonfmu's ModelStructure: expected Outputs, no InitialUnknowns")
    initial = ET.SubElement(structure, "InitialUnknowns")
    for unknown in outputs:
        unknown.set("dependencies", "")
        ET.SubElement(initial, "Unknown", index=unknown.attrib["index"])
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def export(kind: str, out: str | Path) -> Exported:
    """Write trackmj's plant (the track with the built-in hydraulics) as an FMI 2.0
    co-simulation FMU.

    Parameters
    ----------
    kind : {"plant"}
        The track with the built-in hydraulics (valve command in, sensor signals out);
        "track" is refused: the track alone is exported natively (:mod:`trackmj.fmi.native`).
    out : str or Path
        The .fmu file to write (replaced if it exists).

    Returns
    -------
    Exported
        The FMU and what the importing host needs.
    """
    if kind == "track":
        raise ValueError("fmu export 'track': the track FMU is native (trackmj.fmi.native, "
                         "`trackmj fmu export track`); this exporter writes the plant only")
    if kind not in KINDS:
        raise ValueError(f"fmu export {kind!r}: allowed {', '.join(KINDS)}")
    try:   # local: optional dependency (trackmj[fmi]), needed only to export
        from pythonfmu.builder import FmuBuilder
    except ImportError:
        raise ValueError("exporting an FMU needs pythonfmu: pip install 'trackmj[fmi]'") \
            from None
    out = Path(out)
    if out.suffix != ".fmu":
        raise ValueError(f"-o {out}: the file name must end in .fmu")
    identifier, slave = KINDS[kind]
    site_dirs = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    with tempfile.TemporaryDirectory(prefix="trackmj-export-") as tmp:
        work = Path(tmp)
        script = work / f"{identifier}.py"
        script.write_text(_script(identifier, slave, site_dirs))
        built = work / "build" / f"{identifier}.fmu"
        built.parent.mkdir()
        FmuBuilder.build_FMU(script, dest=built, canGetAndSetFMUstate=True,
                             canSerializeFMUstate=True,
                             canBeInstantiatedOnlyOncePerProcess=False)
        binary = f"binaries/linux64/{identifier}.so"
        with zipfile.ZipFile(built) as zf:
            entries = {name: zf.read(name) for name in zf.namelist()
                       if not name.startswith("binaries/win64/")}
        entries["modelDescription.xml"] = _describe(entries["modelDescription.xml"])
        original = work / "pythonfmu.so"
        original.write_bytes(entries[binary])
        entries[binary] = _build_shim(work, identifier, original).read_bytes()
        entries[f"binaries/linux64/{PYTHONFMU_BINARY}"] = original.read_bytes()
        staged = out.with_name(f".{out.name}.tmp")
        out.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as zf:
            for name, data in entries.items():
                zf.writestr(name, data)
        staged.replace(out)
    soname, libdir = _libpython() or ("", "")
    notes = (f"FMI 2.0 co-simulation, model identifier {identifier}, 1 ms communication "
             "step (positive integer multiples allowed), state save/restore and "
             "serialisation; binary: Linux x86-64 only",
             f"host needs: Python {sys.version_info[0]}.{sys.version_info[1]} "
             f"({libdir}/{soname}) with trackmj; the FMU adds " + ", ".join(site_dirs)
             + " to its sys.path")
    return Exported(out, identifier, notes)
