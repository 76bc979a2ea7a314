/* crankfmu FMU launcher: the binaries/linux64/<id>.so of every crankfmu FMU.
 *
 * pythonfmu 0.7.0's binary (kept in the FMU as binaries/linux64/<id>_pythonfmu.so) leaves the
 * Python C API undefined and expects the host to provide a running, configured interpreter. This
 * launcher makes the FMU run in any FMI host:
 *   1. Python: if the process already has an initialized interpreter (fmpy, libcosimpy, ecospy, a
 *      C host that owns one), it is used as it is. Otherwise the launcher searches a suitable
 *      Python (CRANKFMU_PYTHON, the builder's environment, PATH: python_host.c), loads its
 *      libpython with RTLD_GLOBAL and starts the interpreter with the program name set to that
 *      python, so its environment's pyvenv.cfg / prefix gives its site-packages (numpy, scipy).
 *      The interpreter started here is never finalized (a host may still run FMU code in its
 *      own exit handlers).
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
 * -ldl -lpthread (python_host.c, the part shared with the FMI 3.0 launcher launcher3.c, is
 * included). No Python headers are needed: the few C API functions used are declared in
 * python_host.c and looked up with dlsym.
 */
#include "python_host.c"

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

typedef fmi2Component (*InstantiateFn)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                       const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);

/* pythonfmu's fmi2 functions in its binary (python_host.c's `real`), bound once. */
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
    LogFilter log;                 /* what reaches the host's logger */
    int failed;
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
    if (!log_wanted(&inst->log, status >= fmi2Error, category)) return;
    if (inst->host.logger)
        inst->host.logger(inst->host.componentEnvironment, name, status, category, "%s",
                          message);
    else
        fprintf(stderr, "[%s] %s\n", name ? name : "?", message);
}

#define BIND(name)                                                                               \
    if (!(real_##name = dlsym(real, #name))) {                                                   \
        snprintf(error, size, "pythonfmu's binary has no %s", #name);                            \
        return 0;                                                                                \
    }

static int bind_fmi2(char *error, size_t size) {
    if (real_fmi2Instantiate) return 1;
    FMI2_FUNCTIONS(BIND)
    return 1;
}

static void free_record(Instance *inst) {
    clear_log_filter(&inst->log);
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
    int ok = prepare(dir, "pythonfmu", "linux64", &cfg, error, sizeof error);
    if (ok) {
        pthread_mutex_lock(&lock);
        ok = bind_fmi2(error, sizeof error);
        pthread_mutex_unlock(&lock);
    }
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
    inst->log.on = logging_on;
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
    if (!set_log_filter(&inst->log, on, n, categories)) return fmi2Error;
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
