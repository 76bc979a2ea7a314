/* crankfmu FMU launcher for FMI 3.0: the binaries/x86_64-linux/<id>.so of every crankfmu FMI 3.0
 * FMU, in front of pythonfmu3 0.3.4's binary (kept beside it as <id>_pythonfmu3.so). It does
 * for FMI 3.0 what launcher.c does for FMI 2.0 (the Python search, the pre-flight check and the
 * exit order are python_host.c, shared):
 *   - Python: the host's interpreter if one runs, else the first suitable Python of the search
 *     (CRANKFMU_PYTHON, the builder's environment, PATH), started here and never finalized.
 *   - logging: pythonfmu3 calls the host's logMessage without checking it for NULL and without
 *     regard to loggingOn; the launcher gives it its own callback and forwards messages of status
 *     fmi3Error and above always, the others when the host asked (loggingOn,
 *     fmi3SetDebugLogging categories).
 *   - failures: a Python exception is fmi3Fatal in pythonfmu3, which then releases the
 *     instance's Python objects; the launcher returns fmi3Error, marks the instance failed and
 *     refuses later calls except fmi3FreeInstance and fmi3Reset (a fresh pythonfmu3 instance).
 *   - what pythonfmu3 leaves out: fmi3EnterInitializationMode's startTime and tolerance do not
 *     reach Python there; the launcher passes them first with fmi3SetFloat64 on two value
 *     references outside the modelDescription (runtime/slave3.py EXPERIMENT_VRS).
 *     fmi3UpdateDiscreteStates sets only the flags it finds under pythonfmu3's names; the
 *     launcher sets every output flag before. The functions pythonfmu3 does not implement
 *     throw a C++ exception out of a C function there (the host process aborts); the launcher
 *     answers them itself with fmi3Error and a message (REFUSED below).
 * Built by crankfmu/fmu/launcher/__init__.py: cc -O2 -shared -fPIC launcher3.c -ldl -lpthread.
 */
#include "python_host.c"

#include <stdbool.h>
#include <stdint.h>

/* ---- FMI 3.0 types (fmi3PlatformTypes.h, fmi3FunctionTypes.h) ------------------------------ */
typedef void *fmi3Instance;
typedef void *fmi3InstanceEnvironment;
typedef void *fmi3FMUState;
typedef uint32_t fmi3ValueReference;
typedef double fmi3Float64;
typedef int32_t fmi3Int32;
typedef int64_t fmi3Int64;
typedef uint64_t fmi3UInt64;
typedef bool fmi3Boolean;
typedef char fmi3Char;
typedef const fmi3Char *fmi3String;
typedef uint8_t fmi3Byte;
typedef enum { fmi3OK, fmi3Warning, fmi3Discard, fmi3Error, fmi3Fatal } fmi3Status;
typedef void (*fmi3LogMessageCallback)(fmi3InstanceEnvironment, fmi3Status, fmi3String,
                                       fmi3String);

#define EXPERIMENT_VR (1u << 30) /* startTime, then tolerance: runtime/slave3.py EXPERIMENT_VRS */

#define FMI3_FUNCTIONS(X)                                                                        \
    X(fmi3InstantiateCoSimulation) X(fmi3InstantiateModelExchange) X(fmi3FreeInstance)          \
    X(fmi3EnterInitializationMode) X(fmi3ExitInitializationMode) X(fmi3EnterEventMode)          \
    X(fmi3Terminate) X(fmi3Reset) X(fmi3GetFloat64) X(fmi3GetInt32) X(fmi3GetInt64)             \
    X(fmi3GetUInt64) X(fmi3GetBoolean) X(fmi3GetString) X(fmi3SetFloat64) X(fmi3SetInt32)       \
    X(fmi3SetInt64) X(fmi3SetUInt64) X(fmi3SetBoolean) X(fmi3SetString) X(fmi3GetFMUState)      \
    X(fmi3SetFMUState) X(fmi3FreeFMUState) X(fmi3SerializedFMUStateSize)                        \
    X(fmi3SerializeFMUState) X(fmi3DeserializeFMUState) X(fmi3GetDirectionalDerivative)         \
    X(fmi3EnterConfigurationMode) X(fmi3ExitConfigurationMode) X(fmi3UpdateDiscreteStates)      \
    X(fmi3EnterContinuousTimeMode) X(fmi3CompletedIntegratorStep) X(fmi3SetTime)                \
    X(fmi3SetContinuousStates) X(fmi3GetContinuousStateDerivatives) X(fmi3GetEventIndicators)   \
    X(fmi3GetContinuousStates) X(fmi3GetNominalsOfContinuousStates)                             \
    X(fmi3GetNumberOfEventIndicators) X(fmi3GetNumberOfContinuousStates) X(fmi3EnterStepMode)   \
    X(fmi3GetOutputDerivatives) X(fmi3DoStep)
#define REAL(name) static void *real_##name;
FMI3_FUNCTIONS(REAL)

#define BIND(name)                                                                               \
    if (!(real_##name = dlsym(real, #name))) {                                                   \
        snprintf(error, size, "pythonfmu3's binary has no %s", #name);                           \
        return 0;                                                                                \
    }

static int bind_fmi3(char *error, size_t size) {
    if (real_fmi3InstantiateCoSimulation) return 1;
    FMI3_FUNCTIONS(BIND)
    return 1;
}

/* ---- the instance record -------------------------------------------------------------------- */
typedef enum { CO_SIMULATION, MODEL_EXCHANGE } Kind;
typedef struct {
    fmi3Instance c;                 /* pythonfmu3's instance */
    Kind kind;
    fmi3InstanceEnvironment host_env;
    fmi3LogMessageCallback host_log;
    LogFilter log;                 /* what reaches the host's logger */
    int failed;
    char *name, *token, *resources;
    fmi3Boolean visible;
} Instance;

static const char *category_of(fmi3Status status) {
    return status >= fmi3Fatal ? "logStatusFatal" : status >= fmi3Error ? "logStatusError"
         : status >= fmi3Warning ? "logStatusWarning" : "logAll";
}

static void say(fmi3LogMessageCallback cb, fmi3InstanceEnvironment env, const char *name,
                fmi3Status status, const char *fmt, ...) __attribute__((format(printf, 5, 6)));

static void say(fmi3LogMessageCallback cb, fmi3InstanceEnvironment env, const char *name,
                fmi3Status status, const char *fmt, ...) {
    char message[8 * TEXT];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(message, sizeof message, fmt, ap);
    va_end(ap);
    if (cb) cb(env, status, category_of(status), message);
    else fprintf(stderr, "[%s] %s: %s\n", category_of(status), name ? name : "?", message);
}

/* pythonfmu3's messages: status >= fmi3Error always, the others as the host asked. */
static void relay_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                         fmi3String message) {
    Instance *inst = (Instance *)env;
    if (!inst || !message) return;
    if (status == fmi3Fatal) status = fmi3Error; /* the launcher returns fmi3Error for it */
    if (!log_wanted(&inst->log, status >= fmi3Error, category)) return;
    if (inst->host_log) inst->host_log(inst->host_env, status, category, message);
    else fprintf(stderr, "[%s] %s\n", inst->name ? inst->name : "?", message);
}

static void free_record(Instance *inst) {
    clear_log_filter(&inst->log);
    free(inst->name); free(inst->token); free(inst->resources);
    free(inst);
}

typedef fmi3Instance (*InstantiateCsFn)(fmi3String, fmi3String, fmi3String, fmi3Boolean,
                                        fmi3Boolean, fmi3Boolean, fmi3Boolean,
                                        const fmi3ValueReference *, size_t,
                                        fmi3InstanceEnvironment, fmi3LogMessageCallback, void *);
typedef fmi3Instance (*InstantiateMeFn)(fmi3String, fmi3String, fmi3String, fmi3Boolean,
                                        fmi3Boolean, fmi3InstanceEnvironment,
                                        fmi3LogMessageCallback);

static fmi3Instance instantiate_real(Instance *inst) {
    /* logging on in pythonfmu3; relay_logger filters what reaches the host */
    if (inst->kind == MODEL_EXCHANGE)
        return ((InstantiateMeFn)real_fmi3InstantiateModelExchange)(
            inst->name, inst->token, inst->resources, inst->visible, true, inst, relay_logger);
    return ((InstantiateCsFn)real_fmi3InstantiateCoSimulation)(
        inst->name, inst->token, inst->resources, inst->visible, true, false, false, NULL, 0,
        inst, relay_logger, NULL);
}

static fmi3Instance instantiate(Kind kind, fmi3String name, fmi3String token,
                                fmi3String resources, fmi3Boolean visible, fmi3Boolean logging_on,
                                fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    const char *what = kind == MODEL_EXCHANGE ? "fmi3InstantiateModelExchange"
                                              : "fmi3InstantiateCoSimulation";
    char dir[TEXT], error[8 * TEXT];
    Config cfg;
    uri_to_path(resources, dir, sizeof dir);
    int ok = prepare(dir, "pythonfmu3", "x86_64-linux", &cfg, error, sizeof error);
    if (ok) {
        pthread_mutex_lock(&lock);
        ok = bind_fmi3(error, sizeof error);
        pthread_mutex_unlock(&lock);
    }
    if (!ok) {
        say(log, env, name, fmi3Error, "%s: %s", what, error);
        return NULL;
    }
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->kind = kind;
    inst->host_env = env;
    inst->host_log = log;
    inst->log.on = logging_on;
    inst->name = copy(name);
    inst->token = copy(token);
    inst->resources = copy(resources);
    inst->visible = visible;
    inst->c = instantiate_real(inst);
    if (!inst->c) {
        free_record(inst);
        return NULL; /* pythonfmu3 logged why (forwarded as fmi3Error) */
    }
    return inst;
}

EXPORT fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
    fmi3Boolean logging_on, fmi3Boolean event_mode_used, fmi3Boolean early_return_allowed,
    const fmi3ValueReference required[], size_t n_required, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, void *intermediate_update) {
    (void)event_mode_used; (void)early_return_allowed; (void)required; (void)n_required;
    (void)intermediate_update; /* the modelDescription declares none of these capabilities */
    return instantiate(CO_SIMULATION, name, token, resources, visible, logging_on, env, log);
}

EXPORT fmi3Instance fmi3InstantiateModelExchange(
    fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
    fmi3Boolean logging_on, fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    return instantiate(MODEL_EXCHANGE, name, token, resources, visible, logging_on, env, log);
}

EXPORT fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
    fmi3Boolean logging_on, fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
    void *clock_update, void *lock_preemption, void *unlock_preemption) {
    (void)token; (void)resources; (void)visible; (void)logging_on; (void)clock_update;
    (void)lock_preemption; (void)unlock_preemption;
    say(log, env, name, fmi3Error, "fmi3InstantiateScheduledExecution: this FMU offers "
        "Co-Simulation and Model Exchange only");
    return NULL;
}

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }

EXPORT void fmi3FreeInstance(fmi3Instance c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    if (!inst->failed) ((void (*)(fmi3Instance))real_fmi3FreeInstance)(inst->c);
    free_record(inst);
}

/* A call on a failed instance: refused (its Python objects are gone). */
#define REFUSE_IF_FAILED(inst, fn)                                                               \
    if (inst->failed) {                                                                          \
        say(inst->host_log, inst->host_env, inst->name, fmi3Error, "%s: the instance failed "    \
            "before (see the log); only fmi3FreeInstance and fmi3Reset are possible", fn);       \
        return fmi3Error;                                                                        \
    }

/* pythonfmu3's fmi3Fatal means a Python exception, which released this instance's objects. */
static fmi3Status outcome(Instance *inst, fmi3Status status) {
    if (status == fmi3Fatal) {
        inst->failed = 1;
        return fmi3Error;
    }
    return status;
}

#define FORWARD(fn, type, ...)                                                                   \
    do {                                                                                         \
        Instance *inst = (Instance *)c;                                                          \
        if (!inst) return fmi3Error;                                                             \
        REFUSE_IF_FAILED(inst, #fn)                                                              \
        return outcome(inst, ((type)real_##fn)(inst->c, ##__VA_ARGS__));                        \
    } while (0)

typedef fmi3Status (*Plain)(fmi3Instance);
typedef fmi3Status (*SetFloat64Fn)(fmi3Instance, const fmi3ValueReference *, size_t,
                                   const fmi3Float64 *, size_t);

EXPORT fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n,
                                      const fmi3String categories[]) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi3Error;
    if (!set_log_filter(&inst->log, on, n, categories)) return fmi3Error;
    return fmi3OK; /* pythonfmu3 keeps logging everything; relay_logger filters */
}

/* startTime and tolerance reach the Python slave through the experiment value references. */
EXPORT fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tol_defined,
                                              fmi3Float64 tol, fmi3Float64 start,
                                              fmi3Boolean stop_defined, fmi3Float64 stop) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi3Error;
    REFUSE_IF_FAILED(inst, "fmi3EnterInitializationMode")
    const fmi3ValueReference vrs[2] = {EXPERIMENT_VR, EXPERIMENT_VR + 1};
    const fmi3Float64 values[2] = {start, tol};
    size_t n = tol_defined ? 2 : 1;
    fmi3Status status = outcome(inst, ((SetFloat64Fn)real_fmi3SetFloat64)(inst->c, vrs, n,
                                                                           values, n));
    if (status > fmi3Warning) return status;
    typedef fmi3Status (*Fn)(fmi3Instance, fmi3Boolean, fmi3Float64, fmi3Float64, fmi3Boolean,
                             fmi3Float64);
    return outcome(inst, ((Fn)real_fmi3EnterInitializationMode)(inst->c, tol_defined, tol, start,
                                                                stop_defined, stop));
}

/* An impossible parameter raises in the slave's exit_initialization_mode: pythonfmu3 logs the
 * reason and returns fmi3Fatal; the host gets fmi3Error. */
EXPORT fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi3Error;
    REFUSE_IF_FAILED(inst, "fmi3ExitInitializationMode")
    fmi3Status status = ((Plain)real_fmi3ExitInitializationMode)(inst->c);
    if (status == fmi3Fatal)
        say(inst->host_log, inst->host_env, inst->name, fmi3Error, "fmi3ExitInitializationMode "
            "failed (reason above); reported as fmi3Error: free the instance with "
            "fmi3FreeInstance or reset it with fmi3Reset");
    return outcome(inst, status);
}

EXPORT fmi3Status fmi3Reset(fmi3Instance c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi3Error;
    if (!inst->failed) return outcome(inst, ((Plain)real_fmi3Reset)(inst->c));
    /* pythonfmu3's reset would release the instance's Python objects a second time: start a
     * fresh pythonfmu3 instance instead (the failed one is left, see fmi3FreeInstance). */
    fmi3Instance fresh = instantiate_real(inst);
    if (!fresh) return fmi3Error;
    inst->c = fresh;
    inst->failed = 0;
    return fmi3OK;
}

EXPORT fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *need_update,
                                           fmi3Boolean *terminate, fmi3Boolean *nominals_changed,
                                           fmi3Boolean *values_changed,
                                           fmi3Boolean *next_time_defined,
                                           fmi3Float64 *next_time) {
    *need_update = *terminate = *nominals_changed = *values_changed = false;
    *next_time_defined = false;
    *next_time = 0.0;
    FORWARD(fmi3UpdateDiscreteStates,
            fmi3Status (*)(fmi3Instance, fmi3Boolean *, fmi3Boolean *, fmi3Boolean *,
                           fmi3Boolean *, fmi3Boolean *, fmi3Float64 *),
            need_update, terminate, nominals_changed, values_changed, next_time_defined,
            next_time);
}

EXPORT fmi3Status fmi3EnterEventMode(fmi3Instance c) { FORWARD(fmi3EnterEventMode, Plain); }
EXPORT fmi3Status fmi3Terminate(fmi3Instance c) { FORWARD(fmi3Terminate, Plain); }
EXPORT fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) {
    FORWARD(fmi3EnterConfigurationMode, Plain);
}
EXPORT fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) {
    FORWARD(fmi3ExitConfigurationMode, Plain);
}
EXPORT fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
    FORWARD(fmi3EnterContinuousTimeMode, Plain);
}
EXPORT fmi3Status fmi3EnterStepMode(fmi3Instance c) { FORWARD(fmi3EnterStepMode, Plain); }

#define GETSET(fn, T)                                                                            \
    EXPORT fmi3Status fn(fmi3Instance c, const fmi3ValueReference vr[], size_t n, T value[],     \
                         size_t n_values) {                                                      \
        FORWARD(fn, fmi3Status (*)(fmi3Instance, const fmi3ValueReference *, size_t, T *,        \
                                   size_t), vr, n, value, n_values);                             \
    }
GETSET(fmi3GetFloat64, fmi3Float64)
GETSET(fmi3GetInt32, fmi3Int32)
GETSET(fmi3GetInt64, fmi3Int64)
GETSET(fmi3GetUInt64, fmi3UInt64)
GETSET(fmi3GetBoolean, fmi3Boolean)
GETSET(fmi3GetString, fmi3String)
GETSET(fmi3SetFloat64, const fmi3Float64)
GETSET(fmi3SetInt32, const fmi3Int32)
GETSET(fmi3SetInt64, const fmi3Int64)
GETSET(fmi3SetUInt64, const fmi3UInt64)
GETSET(fmi3SetBoolean, const fmi3Boolean)
GETSET(fmi3SetString, const fmi3String)

EXPORT fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s) {
    FORWARD(fmi3GetFMUState, fmi3Status (*)(fmi3Instance, fmi3FMUState *), s);
}
EXPORT fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s) {
    FORWARD(fmi3SetFMUState, fmi3Status (*)(fmi3Instance, fmi3FMUState), s);
}
EXPORT fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s) {
    FORWARD(fmi3FreeFMUState, fmi3Status (*)(fmi3Instance, fmi3FMUState *), s);
}
EXPORT fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *size) {
    FORWARD(fmi3SerializedFMUStateSize, fmi3Status (*)(fmi3Instance, fmi3FMUState, size_t *),
            s, size);
}
EXPORT fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte out[],
                                        size_t size) {
    FORWARD(fmi3SerializeFMUState,
            fmi3Status (*)(fmi3Instance, fmi3FMUState, fmi3Byte *, size_t), s, out, size);
}
EXPORT fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte in[], size_t size,
                                          fmi3FMUState *s) {
    FORWARD(fmi3DeserializeFMUState,
            fmi3Status (*)(fmi3Instance, const fmi3Byte *, size_t, fmi3FMUState *), in, size, s);
}
EXPORT fmi3Status fmi3GetDirectionalDerivative(
    fmi3Instance c, const fmi3ValueReference unknowns[], size_t n_unknowns,
    const fmi3ValueReference knowns[], size_t n_knowns, const fmi3Float64 seed[], size_t n_seed,
    fmi3Float64 sensitivity[], size_t n_sensitivity) {
    FORWARD(fmi3GetDirectionalDerivative,
            fmi3Status (*)(fmi3Instance, const fmi3ValueReference *, size_t,
                           const fmi3ValueReference *, size_t, const fmi3Float64 *, size_t,
                           fmi3Float64 *, size_t),
            unknowns, n_unknowns, knowns, n_knowns, seed, n_seed, sensitivity, n_sensitivity);
}
EXPORT fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[],
                                           size_t n, const fmi3Int32 order[],
                                           fmi3Float64 values[], size_t n_values) {
    FORWARD(fmi3GetOutputDerivatives,
            fmi3Status (*)(fmi3Instance, const fmi3ValueReference *, size_t, const fmi3Int32 *,
                           fmi3Float64 *, size_t), vr, n, order, values, n_values);
}
EXPORT fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h,
                             fmi3Boolean no_prior, fmi3Boolean *event_handling_needed,
                             fmi3Boolean *terminate, fmi3Boolean *early_return,
                             fmi3Float64 *last_successful_time) {
    *event_handling_needed = *terminate = *early_return = false;
    FORWARD(fmi3DoStep,
            fmi3Status (*)(fmi3Instance, fmi3Float64, fmi3Float64, fmi3Boolean, fmi3Boolean *,
                           fmi3Boolean *, fmi3Boolean *, fmi3Float64 *),
            t, h, no_prior, event_handling_needed, terminate, early_return,
            last_successful_time);
}

/* ---- Model Exchange ------------------------------------------------------------------------- */
EXPORT fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean no_prior,
                                              fmi3Boolean *enter_event_mode,
                                              fmi3Boolean *terminate) {
    FORWARD(fmi3CompletedIntegratorStep,
            fmi3Status (*)(fmi3Instance, fmi3Boolean, fmi3Boolean *, fmi3Boolean *), no_prior,
            enter_event_mode, terminate);
}
EXPORT fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) {
    FORWARD(fmi3SetTime, fmi3Status (*)(fmi3Instance, fmi3Float64), t);
}
#define VECTOR(fn, T)                                                                            \
    EXPORT fmi3Status fn(fmi3Instance c, T values[], size_t n) {                                 \
        FORWARD(fn, fmi3Status (*)(fmi3Instance, T *, size_t), values, n);                       \
    }
VECTOR(fmi3SetContinuousStates, const fmi3Float64)
VECTOR(fmi3GetContinuousStateDerivatives, fmi3Float64)
VECTOR(fmi3GetEventIndicators, fmi3Float64)
VECTOR(fmi3GetContinuousStates, fmi3Float64)
VECTOR(fmi3GetNominalsOfContinuousStates, fmi3Float64)
EXPORT fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) {
    FORWARD(fmi3GetNumberOfEventIndicators, fmi3Status (*)(fmi3Instance, size_t *), n);
}
EXPORT fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) {
    FORWARD(fmi3GetNumberOfContinuousStates, fmi3Status (*)(fmi3Instance, size_t *), n);
}

/* ---- what pythonfmu3 0.3.4 does not implement (it would throw out of a C function) --------- */
static fmi3Status refused(fmi3Instance c, const char *fn) {
    Instance *inst = (Instance *)c;
    if (inst)
        say(inst->host_log, inst->host_env, inst->name, fmi3Error, "%s is not supported by this "
            "FMU (its variables are Float64 and Boolean; no clocks, no dependencies API)", fn);
    return fmi3Error;
}
#define REFUSED(fn, ...)                                                                         \
    EXPORT fmi3Status fn(fmi3Instance c, __VA_ARGS__) { return refused(c, #fn); }
#define REFUSED_GETSET(suffix, T)                                                                \
    REFUSED(fmi3Get##suffix, const fmi3ValueReference vr[], size_t n, T v[], size_t nv)          \
    REFUSED(fmi3Set##suffix, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-parameter"
REFUSED_GETSET(Float32, float)
REFUSED_GETSET(Int8, int8_t)
REFUSED_GETSET(Int16, int16_t)
REFUSED_GETSET(UInt8, uint8_t)
REFUSED_GETSET(UInt16, uint16_t)
REFUSED_GETSET(UInt32, uint32_t)
REFUSED(fmi3GetBinary, const fmi3ValueReference vr[], size_t n, size_t sizes[],
        const fmi3Byte *v[], size_t nv)
REFUSED(fmi3SetBinary, const fmi3ValueReference vr[], size_t n, const size_t sizes[],
        const fmi3Byte *const v[], size_t nv)
REFUSED(fmi3GetClock, const fmi3ValueReference vr[], size_t n, fmi3Boolean v[])
REFUSED(fmi3SetClock, const fmi3ValueReference vr[], size_t n, const fmi3Boolean v[])
REFUSED(fmi3GetNumberOfVariableDependencies, fmi3ValueReference vr, size_t *n)
REFUSED(fmi3GetVariableDependencies, fmi3ValueReference dependent, size_t element[],
        fmi3ValueReference independents[], size_t element_independents[], int kinds[], size_t n)
REFUSED(fmi3GetAdjointDerivative, const fmi3ValueReference unknowns[], size_t nu,
        const fmi3ValueReference knowns[], size_t nk, const fmi3Float64 seed[], size_t ns,
        fmi3Float64 sensitivity[], size_t nsens)
REFUSED(fmi3GetIntervalDecimal, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[],
        int qualifiers[])
REFUSED(fmi3GetIntervalFraction, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
        fmi3UInt64 r[], int qualifiers[])
REFUSED(fmi3GetShiftDecimal, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[])
REFUSED(fmi3GetShiftFraction, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
        fmi3UInt64 r[])
REFUSED(fmi3SetIntervalDecimal, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[])
REFUSED(fmi3SetIntervalFraction, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
        const fmi3UInt64 r[])
REFUSED(fmi3SetShiftDecimal, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[])
REFUSED(fmi3SetShiftFraction, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
        const fmi3UInt64 r[])
REFUSED(fmi3ActivateModelPartition, fmi3ValueReference clock, fmi3Float64 t)
#pragma GCC diagnostic pop
EXPORT fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
    return refused(c, "fmi3EvaluateDiscreteStates");
}
