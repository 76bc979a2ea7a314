/* crankfmu FMU launcher: the binaries/linux64/<id>.so of every crankfmu FMU.
 *
 * pythonfmu 0.7.0's binary (kept in the FMU as binaries/linux64/<id>_pythonfmu.so) leaves the
 * Python C API undefined and expects the host to provide a running, configured interpreter. This
 * launcher makes the FMU run in any FMI host:
 *   1. Python: if the process already has an initialized interpreter (fmpy, libcosimpy, ecospy, a
 *      C host that owns one), it is used as it is. Otherwise the launcher loads libpython with
 *      RTLD_GLOBAL and starts the interpreter with the program name set to the python executable
 *      of the environment recorded at build time (resources/crankfmu_launcher.txt), so that
 *      environment's pyvenv.cfg / prefix gives its site-packages (numpy, scipy). The variable
 *      CRANKFMU_PYTHON (a python executable, or an environment / installation folder) overrides
 *      the environment, CRANKFMU_LIBPYTHON the library. The interpreter started here is never
 *      finalized (a host may still run FMU code in its own exit handlers).
 *   2. Pre-flight: before the first instance, the packages the runtime needs (numpy, scipy) are
 *      looked up (importlib.util.find_spec: found, not imported; scipy is off the default path,
 *      and importing it cost every process ~10 ms); if one is missing, fmi2Instantiate returns
 *      NULL and logs what is missing, in which Python, and how to point the FMU at another
 *      environment.
 *   3. Forwarding: every fmi2 function goes to the pythonfmu binary. The launcher keeps a small
 *      instance record around pythonfmu's component:
 *      - logging: pythonfmu logs nothing unless loggingOn; the launcher instantiates it with
 *        logging on and forwards messages of status fmi2Error and above always, the others
 *        when the host asked for them (loggingOn, fmi2SetDebugLogging with its categories);
 *        the message is passed as a string ("%s"), never as a format.
 *      - failures: pythonfmu turns every Python exception into fmi2Fatal and releases the
 *        instance's Python objects at once (handle_py_exception -> cleanPyObject), without
 *        clearing its pointers; its fmi2FreeInstance and fmi2Reset would release them a second
 *        time. The launcher reports such a failure as fmi2Error (the instance alone failed; an
 *        impossible parameter ends fmi2ExitInitializationMode this way), marks the instance
 *        failed, refuses further calls except fmi2FreeInstance (which then frees only the
 *        launcher's record and leaves pythonfmu's few hundred bytes: freeing them would release
 *        Python objects twice) and fmi2Reset (which instantiates a fresh pythonfmu instance).
 *   4. Exit order: pythonfmu's library destructor resets a static std::shared_ptr after that
 *      shared_ptr's own static destructor ran (glibc runs exit handlers before library
 *      destructors); the launcher registers, after loading the binary, an exit handler that
 *      calls the binary's finalizePythonInterpreter first, so both find an empty pointer. The
 *      launcher and the pythonfmu binary are pinned (RTLD_NODELETE): Python objects may point
 *      into pythonfmu's code for as long as the interpreter lives.
 *
 * Built by crankfmu/fmu/build.py with the system C compiler: cc -O2 -shared -fPIC launcher.c
 * -ldl -lpthread. No Python headers are needed: the few C API functions used are declared here
 * and looked up with dlsym.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <wchar.h>

#define EXPORT __attribute__((visibility("default")))

/* ---- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) ------------------------------ */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated }
    fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* ---- what the build records (resources/crankfmu_launcher.txt) ----------------------------- */
#define TEXT 4096
typedef struct {
    char model[256];        /* modelIdentifier: the pythonfmu binary is <model>_pythonfmu.so */
    char python[TEXT];      /* the environment's python executable */
    char libpython[TEXT];   /* its libpython (sysconfig LIBDIR/LDLIBRARY) */
    char version[32];       /* e.g. 3.11 */
    char requires[TEXT];    /* packages looked up before the first instance, space separated */
} Config;

/* ---- Python C API, looked up at run time ---------------------------------------------------- */
typedef struct {
    int (*IsInitialized)(void);
    void (*InitializeEx)(int);
    void (*SetProgramName)(const wchar_t *);
    wchar_t *(*DecodeLocale)(const char *, size_t *);
    void *(*SaveThread)(void);
    int (*GILEnsure)(void);
    void (*GILRelease)(int);
    void *(*DictNew)(void);
    void *(*RunString)(const char *, int, void *, void *, void *);
    void *(*DictGetItemString)(void *, const char *);
    const char *(*AsUTF8)(void *);
    void (*DecRef)(void *);
    void (*ErrPrint)(void);
} PyApi;
#define PY_FILE_INPUT 257

typedef fmi2Component (*InstantiateFn)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                       const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);

/* The pythonfmu binary of this FMU: one per loaded copy of the launcher. */
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static void *real;                 /* dlopen handle, NULL until the first fmi2Instantiate */
static void (*real_finalize)(void);
static PyApi py;
static int py_ready;
static int py_started_here;        /* this launcher started the interpreter */

#define REAL(name) static void *real_##name;
#define FMI2_FUNCTIONS(X)                                                                        \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetDebugLogging) X(fmi2SetupExperiment)          \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset)    \
    X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal)            \
    X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate)    \
    X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate)                   \
    X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative) X(fmi2SetRealInputDerivatives)     \
    X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep) X(fmi2GetStatus)              \
    X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus) X(fmi2GetStringStatus)
FMI2_FUNCTIONS(REAL)

/* ---- the instance record -------------------------------------------------------------------- */
typedef struct {
    fmi2Component c;               /* pythonfmu's component */
    fmi2CallbackFunctions host;    /* the host's callbacks */
    fmi2CallbackFunctions mine;    /* given to pythonfmu: our logger, environment = this record */
    int logging_on, failed;
    size_t n_categories;
    char **categories;
    char *name, *guid, *resources;
    fmi2Type type;
    fmi2Boolean visible;
} Instance;

static void host_log(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status,
                     const char *fmt, ...) __attribute__((format(printf, 4, 5)));

static void host_log(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status,
                     const char *fmt, ...) {
    char message[8 * TEXT];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(message, sizeof message, fmt, ap);
    va_end(ap);
    const char *category = status >= fmi2Fatal ? "logStatusFatal"
                         : status >= fmi2Error ? "logStatusError"
                         : status >= fmi2Warning ? "logStatusWarning" : "logAll";
    if (cb && cb->logger)
        cb->logger(cb->componentEnvironment, name ? name : "?", status, category, "%s", message);
    else
        fprintf(stderr, "[%s] %s\n", category, message);
}

/* pythonfmu's messages: status >= fmi2Error always, the others as the host asked. pythonfmu
 * passes the message with no arguments; it is forwarded as a string, never as a format. */
static void relay_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                         fmi2String category, fmi2String message, ...) {
    Instance *inst = (Instance *)env;
    if (!inst || !message) return;
    /* pythonfmu logs every Python exception as fmi2Fatal; the launcher returns fmi2Error for
     * it (see outcome()), and the message says the same */
    if (status == fmi2Fatal) status = fmi2Error;
    int wanted = status >= fmi2Error;
    if (!wanted && inst->logging_on) {
        wanted = inst->n_categories == 0;
        for (size_t i = 0; !wanted && i < inst->n_categories; i++)
            wanted = (category && !strcmp(category, inst->categories[i])) ||
                     !strcmp(inst->categories[i], "logAll");
    }
    if (!wanted) return;
    if (inst->host.logger)
        inst->host.logger(inst->host.componentEnvironment, name, status, category, "%s",
                          message);
    else
        fprintf(stderr, "[%s] %s\n", name ? name : "?", message);
}

/* ---- configuration -------------------------------------------------------------------------- */
static void trim(char *s) {
    size_t n = strlen(s);
    while (n && (s[n - 1] == '\n' || s[n - 1] == '\r' || s[n - 1] == ' ')) s[--n] = 0;
}

static int read_config(const char *resources, Config *cfg, char *error, size_t size) {
    char path[TEXT + 64], line[2 * TEXT];
    snprintf(path, sizeof path, "%s/crankfmu_launcher.txt", resources);
    FILE *in = fopen(path, "r");
    if (!in) {
        snprintf(error, size, "cannot read %s (the FMU is incomplete)", path);
        return 0;
    }
    memset(cfg, 0, sizeof *cfg);
    while (fgets(line, sizeof line, in)) {
        trim(line);
        char *eq = strstr(line, " = ");
        if (line[0] == '#' || !eq) continue;
        *eq = 0;
        const char *value = eq + 3;
        if (!strcmp(line, "model")) snprintf(cfg->model, sizeof cfg->model, "%s", value);
        else if (!strcmp(line, "python")) snprintf(cfg->python, sizeof cfg->python, "%s", value);
        else if (!strcmp(line, "libpython"))
            snprintf(cfg->libpython, sizeof cfg->libpython, "%s", value);
        else if (!strcmp(line, "python_version"))
            snprintf(cfg->version, sizeof cfg->version, "%s", value);
        else if (!strcmp(line, "requires"))
            snprintf(cfg->requires, sizeof cfg->requires, "%s", value);
    }
    fclose(in);
    if (!cfg->model[0] || !cfg->version[0]) {
        snprintf(error, size, "%s lacks 'model' or 'python_version'", path);
        return 0;
    }
    return 1;
}

static int is_file(const char *p) { struct stat st; return !stat(p, &st) && S_ISREG(st.st_mode); }
static int is_dir(const char *p) { struct stat st; return !stat(p, &st) && S_ISDIR(st.st_mode); }

/* The python executable of CRANKFMU_PYTHON: the file itself, or <folder>/bin/python<version>,
 * <folder>/bin/python3 for an environment or installation folder. */
static int override_python(const Config *cfg, char *out, size_t size) {
    const char *given = getenv("CRANKFMU_PYTHON");
    if (!given || !given[0]) return 0;
    if (is_dir(given)) {
        const char *names[] = {"python", "python3", NULL};
        snprintf(out, size, "%s/bin/python%s", given, cfg->version);
        for (int i = 0; names[i] && !is_file(out); i++)
            snprintf(out, size, "%s/bin/%s", given, names[i]);
    } else snprintf(out, size, "%s", given);
    return 1;
}

/* Candidates for libpython of a python executable: from its venv's pyvenv.cfg "home", else
 * beside its own prefix (<exe dir>/../lib). */
static void libpython_beside(const char *exe, const char *version, char *out, size_t size) {
    char dir[TEXT], cfgpath[TEXT + 32], line[TEXT], home[TEXT] = "";
    out[0] = 0;
    snprintf(dir, sizeof dir, "%s", exe);
    char *slash = strrchr(dir, '/');
    if (!slash) return;
    *slash = 0;
    for (int up = 0; up < 2 && !home[0]; up++) {
        snprintf(cfgpath, sizeof cfgpath, up ? "%s/../pyvenv.cfg" : "%s/pyvenv.cfg", dir);
        FILE *in = fopen(cfgpath, "r");
        if (!in) continue;
        while (fgets(line, sizeof line, in)) {
            trim(line);
            if (!strncmp(line, "home", 4)) {
                char *v = strchr(line, '=');
                if (v) { v++; while (*v == ' ') v++; snprintf(home, sizeof home, "%s", v); }
            }
        }
        fclose(in);
    }
    const char *bin = home[0] ? home : dir;
    const char *forms[] = {"%s/../lib/libpython%s.so.1.0", "%s/../lib/libpython%s.so", NULL};
    for (int i = 0; forms[i]; i++) {
        snprintf(out, size, forms[i], bin, version);
        if (is_file(out)) return;
    }
    out[0] = 0;
}

#define PY_SYMBOL(field, name)                                                                   \
    if (!(*(void **)&py.field = dlsym(lib, name))) {                                             \
        snprintf(error, size, "%s has no %s: not a Python %s library", where, name, version);    \
        return 0;                                                                                \
    }

static int bind_python(void *lib, const char *where, const char *version, char *error,
                       size_t size) {
    PY_SYMBOL(IsInitialized, "Py_IsInitialized")
    PY_SYMBOL(InitializeEx, "Py_InitializeEx")
    PY_SYMBOL(SetProgramName, "Py_SetProgramName")
    PY_SYMBOL(DecodeLocale, "Py_DecodeLocale")
    PY_SYMBOL(SaveThread, "PyEval_SaveThread")
    PY_SYMBOL(GILEnsure, "PyGILState_Ensure")
    PY_SYMBOL(GILRelease, "PyGILState_Release")
    PY_SYMBOL(DictNew, "PyDict_New")
    PY_SYMBOL(RunString, "PyRun_StringFlags")
    PY_SYMBOL(DictGetItemString, "PyDict_GetItemString")
    PY_SYMBOL(AsUTF8, "PyUnicode_AsUTF8")
    PY_SYMBOL(DecRef, "Py_DecRef")
    PY_SYMBOL(ErrPrint, "PyErr_Print")
    return 1;
}

#define HOW_TO_POINT                                                                             \
    "Set CRANKFMU_PYTHON to the python executable (or the folder) of a Python %s environment "  \
    "that has %s installed (and CRANKFMU_LIBPYTHON to its libpython%s.so if that is not found "  \
    "beside it); see the FMU's documentation/index.html, \"Using the FMUs in other tools\"."

/* Make sure an initialized interpreter runs in this process; start one if needed. */
static int ensure_python(const Config *cfg, char *error, size_t size) {
    if (py_ready) return 1;
    char python[TEXT], libpython[TEXT] = "";
    int overridden = override_python(cfg, python, sizeof python);
    if (!overridden) snprintf(python, sizeof python, "%s", cfg->python);
    void *lib = dlopen(NULL, RTLD_NOW);  /* the process: a Python host or a host linking it */
    if (lib && dlsym(lib, "Py_IsInitialized")) {
        if (!bind_python(lib, "this process", cfg->version, error, size)) return 0;
    } else {
        const char *lp = getenv("CRANKFMU_LIBPYTHON");
        if (lp && lp[0]) snprintf(libpython, sizeof libpython, "%s", lp);
        else if (overridden) libpython_beside(python, cfg->version, libpython, sizeof libpython);
        else snprintf(libpython, sizeof libpython, "%s", cfg->libpython);
        char soname[64], tried[3 * TEXT];
        snprintf(soname, sizeof soname, "libpython%s.so.1.0", cfg->version);
        lib = libpython[0] ? dlopen(libpython, RTLD_NOW | RTLD_GLOBAL) : NULL;
        snprintf(tried, sizeof tried, "%s: %s", libpython[0] ? libpython : "(none found)",
                 libpython[0] && !lib ? dlerror() : "not found");
        if (!lib) lib = dlopen(soname, RTLD_NOW | RTLD_GLOBAL); /* the loader's search path */
        if (!lib) {
            snprintf(error, size, "Python %s is not available: libpython not loaded (%s; %s: "
                     "%s). " HOW_TO_POINT, cfg->version, tried, soname, dlerror(), cfg->version,
                     cfg->requires, cfg->version);
            return 0;
        }
        if (!bind_python(lib, libpython[0] ? libpython : soname, cfg->version, error, size))
            return 0;
    }
    if (!py.IsInitialized()) {
        if (!is_file(python)) {
            snprintf(error, size, "%s %s: no python executable there. " HOW_TO_POINT,
                     overridden ? "CRANKFMU_PYTHON gives" : "the environment recorded at build "
                     "time is gone:", python, cfg->version, cfg->requires, cfg->version);
            return 0;
        }
        /* The program name makes Python find the environment: a venv's pyvenv.cfg beside it
         * adds the venv's site-packages; an installation's prefix is found from it. */
        wchar_t *program = py.DecodeLocale(python, NULL);
        if (program) py.SetProgramName(program); /* kept: Python uses it until exit */
        py.InitializeEx(0);                       /* 0: no signal handlers in the host */
        py.SaveThread();                          /* release the GIL; pythonfmu takes it */
        py_started_here = 1;
    }
    py_ready = 1;
    return 1;
}

/* Find the packages the runtime needs; on failure write what is missing into `error`. */
static int preflight(const Config *cfg, char *error, size_t size) {
    static const char code[] =
        "import sys\n"
        "from importlib.util import find_spec\n"
        "missing = []\n"
        "for name in requires.split():\n"
        "    try:\n"
        "        if find_spec(name) is None:\n"
        "            missing.append(f'{name} (ModuleNotFoundError: No module named {name!r})')\n"
        "    except Exception as err:\n"
        "        missing.append(f'{name} ({type(err).__name__}: {err})')\n"
        "message = ''\n"
        "if missing:\n"
        "    message = ('Python package(s) missing: ' + '; '.join(missing) + '. The FMU runs in '\n"
        "               f'the Python at {sys.executable} (prefix {sys.prefix}, Python '\n"
        "               f'{sys.version.split()[0]}), which cannot import them.')\n";
    int ok = 1;
    int gil = py.GILEnsure();
    void *globals = py.DictNew();
    char script[sizeof code + TEXT + 64];
    snprintf(script, sizeof script, "requires = '%s'\n%s", cfg->requires, code);
    void *result = globals ? py.RunString(script, PY_FILE_INPUT, globals, globals, NULL) : NULL;
    if (!result) {
        py.ErrPrint();
        snprintf(error, size, "the pre-flight check could not run in Python (traceback on "
                 "stderr)");
        ok = 0;
    } else {
        py.DecRef(result);
        void *message = py.DictGetItemString(globals, "message"); /* borrowed */
        const char *text = message ? py.AsUTF8(message) : NULL;
        if (text && text[0]) {
            if (py_started_here)
                snprintf(error, size, "%s " HOW_TO_POINT, text, cfg->version, cfg->requires,
                         cfg->version);
            else
                snprintf(error, size, "%s This host runs Python itself, and the FMU uses that "
                         "interpreter: install %s into it, or run the host from an environment "
                         "that has them (CRANKFMU_PYTHON applies to hosts that do not run "
                         "Python).", text, cfg->requires);
            ok = 0;
        }
    }
    if (globals) py.DecRef(globals);
    py.GILRelease(gil);
    return ok;
}

static void release_at_exit(void) {
    if (real_finalize) real_finalize();
}

/* This launcher's own file, for the path of the pythonfmu binary beside it. */
static int own_dir(char *out, size_t size) {
    Dl_info info;
    if (!dladdr((void *)&own_dir, &info) || !info.dli_fname) return 0;
    snprintf(out, size, "%s", info.dli_fname);
    char *slash = strrchr(out, '/');
    if (!slash) return 0;
    *slash = 0;
    return 1;
}

#define BIND(name)                                                                               \
    if (!(real_##name = dlsym(real, #name))) {                                                   \
        snprintf(error, size, "%s has no %s", path, #name);                                      \
        return 0;                                                                                \
    }

static int load_real(const Config *cfg, const char *resources, char *error, size_t size) {
    if (real) return 1;
    char dir[TEXT], path[2 * TEXT];
    if (own_dir(dir, sizeof dir)) snprintf(path, sizeof path, "%s/%s_pythonfmu.so", dir,
                                           cfg->model);
    if (!own_dir(dir, sizeof dir) || !is_file(path))
        snprintf(path, sizeof path, "%s/../binaries/linux64/%s_pythonfmu.so", resources,
                 cfg->model);
    real = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    if (!real) {
        snprintf(error, size, "cannot load pythonfmu's binary: %s", dlerror());
        return 0;
    }
    FMI2_FUNCTIONS(BIND)
    *(void **)&real_finalize = dlsym(real, "finalizePythonInterpreter");
    /* Registered after the binary's static constructors: runs before its static destructors. */
    atexit(release_at_exit);
    /* Pin this launcher too: the exit handler above lives in it. */
    Dl_info info;
    if (dladdr((void *)&load_real, &info) && info.dli_fname)
        dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
    return 1;
}

/* "file:///a%20b/resources" -> "/a b/resources" */
static void uri_to_path(const char *uri, char *out, size_t size) {
    const char *p = uri ? uri : "";
    if (!strncmp(p, "file://", 7)) p += 7;
    if (!strncmp(p, "localhost/", 10)) p += 9;
    size_t n = 0;
    for (; *p && n + 1 < size; p++) {
        unsigned int byte;
        if (p[0] == '%' && sscanf(p + 1, "%2x", &byte) == 1) { out[n++] = (char)byte; p += 2; }
        else out[n++] = *p;
    }
    out[n] = 0;
    while (n > 1 && out[n - 1] == '/') out[--n] = 0;
}

static char *copy(const char *s) {
    if (!s) return NULL;
    char *c = malloc(strlen(s) + 1);
    if (c) strcpy(c, s);
    return c;
}

static void free_record(Instance *inst) {
    for (size_t i = 0; i < inst->n_categories; i++) free(inst->categories[i]);
    free(inst->categories);
    free(inst->name); free(inst->guid); free(inst->resources);
    free(inst);
}

static fmi2Component instantiate_real(Instance *inst) {
    /* logging on in pythonfmu; relay_logger filters what reaches the host */
    return ((InstantiateFn)real_fmi2Instantiate)(inst->name, inst->type, inst->guid,
                                                 inst->resources, &inst->mine, inst->visible, 1);
}

EXPORT fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                                     fmi2String resources, const fmi2CallbackFunctions *cb,
                                     fmi2Boolean visible, fmi2Boolean logging_on) {
    char dir[TEXT], error[8 * TEXT];
    Config cfg;
    if (!cb || !cb->logger) {
        fprintf(stderr, "%s: fmi2Instantiate: no callback functions (FMI 2.0 requires a logger)\n",
                name ? name : "?");
        return NULL;
    }
    uri_to_path(resources, dir, sizeof dir);
    pthread_mutex_lock(&lock);
    int ok = read_config(dir, &cfg, error, sizeof error) &&
             ensure_python(&cfg, error, sizeof error) &&
             preflight(&cfg, error, sizeof error) &&
             load_real(&cfg, dir, error, sizeof error);
    pthread_mutex_unlock(&lock);
    if (!ok) {
        host_log(cb, name, fmi2Error, "fmi2Instantiate: %s", error);
        return NULL;
    }
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->host = *cb;
    inst->mine = *cb;
    inst->mine.logger = relay_logger;
    inst->mine.componentEnvironment = inst;
    inst->logging_on = logging_on;
    inst->name = copy(name);
    inst->guid = copy(guid);
    inst->resources = copy(resources);
    inst->type = type;
    inst->visible = visible;
    inst->c = instantiate_real(inst);
    if (!inst->c) {
        free_record(inst);
        return NULL; /* pythonfmu logged why (status fmi2Fatal, forwarded) */
    }
    return inst;
}

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    if (!inst->failed) ((void (*)(fmi2Component))real_fmi2FreeInstance)(inst->c);
    free_record(inst);
}

/* A call on a failed instance: refused (its Python objects are gone). */
#define REFUSE_IF_FAILED(inst, fn)                                                               \
    if (inst->failed) {                                                                          \
        host_log(&inst->host, inst->name, fmi2Error, "%s: the instance failed before (see the "  \
                 "log); only fmi2FreeInstance and fmi2Reset are possible", fn);                  \
        return fmi2Error;                                                                        \
    }

/* pythonfmu's fmi2Fatal means a Python exception, which released this instance's objects. */
static fmi2Status outcome(Instance *inst, fmi2Status status) {
    if (status == fmi2Fatal) {
        inst->failed = 1;
        return fmi2Error;
    }
    return status;
}

#define FORWARD(fn, type, ...)                                                                   \
    do {                                                                                         \
        Instance *inst = (Instance *)c;                                                          \
        if (!inst) return fmi2Error;                                                             \
        REFUSE_IF_FAILED(inst, #fn)                                                              \
        return outcome(inst, ((type)real_##fn)(inst->c, ##__VA_ARGS__));                        \
    } while (0)

typedef fmi2Status (*Plain)(fmi2Component);
EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol,
                                      fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    FORWARD(fmi2SetupExperiment,
            fmi2Status (*)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real),
            tol_defined, tol, start, stop_defined, stop);
}
EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    FORWARD(fmi2EnterInitializationMode, Plain);
}
/* An impossible parameter raises in the slave's exit_initialization_mode (or already in a
 * fmi2GetReal of an output in initialization mode): pythonfmu logs the reason and returns
 * fmi2Fatal; the host gets fmi2Error. */
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    REFUSE_IF_FAILED(inst, "fmi2ExitInitializationMode")
    fmi2Status status = ((Plain)real_fmi2ExitInitializationMode)(inst->c);
    if (status == fmi2Fatal)
        host_log(&inst->host, inst->name, fmi2Error, "fmi2ExitInitializationMode failed (reason "
                 "above); reported as fmi2Error: free the instance with fmi2FreeInstance or "
                 "reset it with fmi2Reset");
    return outcome(inst, status);
}
EXPORT fmi2Status fmi2Terminate(fmi2Component c) { FORWARD(fmi2Terminate, Plain); }

EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    if (!inst->failed) return outcome(inst, ((Plain)real_fmi2Reset)(inst->c));
    /* pythonfmu's reset would release the instance's Python objects a second time: start a
     * fresh pythonfmu instance instead (the failed one is left, see fmi2FreeInstance). */
    fmi2Component fresh = instantiate_real(inst);
    if (!fresh) return fmi2Error;
    inst->c = fresh;
    inst->failed = 0;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n,
                                      const fmi2String categories[]) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    for (size_t i = 0; i < inst->n_categories; i++) free(inst->categories[i]);
    free(inst->categories);
    inst->categories = NULL;
    inst->n_categories = 0;
    inst->logging_on = on;
    if (on && n) {
        inst->categories = calloc(n, sizeof *inst->categories);
        if (!inst->categories) return fmi2Error;
        for (size_t i = 0; i < n; i++) inst->categories[i] = copy(categories[i]);
        inst->n_categories = n;
    }
    return fmi2OK; /* pythonfmu keeps logging everything; relay_logger filters */
}

#define GETSET(fn, T)                                                                            \
    EXPORT fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t n, T value[]) {   \
        FORWARD(fn, fmi2Status (*)(fmi2Component, const fmi2ValueReference *, size_t, T *), vr,  \
                n, value);                                                                       \
    }
GETSET(fmi2GetReal, fmi2Real)
GETSET(fmi2GetInteger, fmi2Integer)
GETSET(fmi2GetBoolean, fmi2Boolean)
GETSET(fmi2GetString, fmi2String)
GETSET(fmi2SetReal, const fmi2Real)
GETSET(fmi2SetInteger, const fmi2Integer)
GETSET(fmi2SetBoolean, const fmi2Boolean)
GETSET(fmi2SetString, const fmi2String)

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    FORWARD(fmi2GetFMUstate, fmi2Status (*)(fmi2Component, fmi2FMUstate *), s);
}
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    FORWARD(fmi2SetFMUstate, fmi2Status (*)(fmi2Component, fmi2FMUstate), s);
}
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    FORWARD(fmi2FreeFMUstate, fmi2Status (*)(fmi2Component, fmi2FMUstate *), s);
}
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    FORWARD(fmi2SerializedFMUstateSize, fmi2Status (*)(fmi2Component, fmi2FMUstate, size_t *),
            s, size);
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte out[],
                                        size_t size) {
    FORWARD(fmi2SerializeFMUstate,
            fmi2Status (*)(fmi2Component, fmi2FMUstate, fmi2Byte *, size_t), s, out, size);
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte in[], size_t size,
                                          fmi2FMUstate *s) {
    FORWARD(fmi2DeSerializeFMUstate,
            fmi2Status (*)(fmi2Component, const fmi2Byte *, size_t, fmi2FMUstate *), in, size,
            s);
}
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[],
                                               size_t nu, const fmi2ValueReference z[],
                                               size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    FORWARD(fmi2GetDirectionalDerivative,
            fmi2Status (*)(fmi2Component, const fmi2ValueReference *, size_t,
                           const fmi2ValueReference *, size_t, const fmi2Real *, fmi2Real *),
            u, nu, z, nz, dv, dz);
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                              size_t n, const fmi2Integer order[],
                                              const fmi2Real value[]) {
    FORWARD(fmi2SetRealInputDerivatives,
            fmi2Status (*)(fmi2Component, const fmi2ValueReference *, size_t,
                           const fmi2Integer *, const fmi2Real *), vr, n, order, value);
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                               size_t n, const fmi2Integer order[],
                                               fmi2Real value[]) {
    FORWARD(fmi2GetRealOutputDerivatives,
            fmi2Status (*)(fmi2Component, const fmi2ValueReference *, size_t,
                           const fmi2Integer *, fmi2Real *), vr, n, order, value);
}
EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    FORWARD(fmi2DoStep, fmi2Status (*)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean), t, h,
            no_prior);
}
EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { FORWARD(fmi2CancelStep, Plain); }

#define STATUS(fn, T)                                                                            \
    EXPORT fmi2Status fn(fmi2Component c, const fmi2StatusKind kind, T *value) {                 \
        FORWARD(fn, fmi2Status (*)(fmi2Component, const fmi2StatusKind, T *), kind, value);      \
    }
STATUS(fmi2GetStatus, fmi2Status)
STATUS(fmi2GetRealStatus, fmi2Real)
STATUS(fmi2GetIntegerStatus, fmi2Integer)
STATUS(fmi2GetBooleanStatus, fmi2Boolean)
STATUS(fmi2GetStringStatus, fmi2String)
