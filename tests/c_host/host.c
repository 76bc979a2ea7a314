/* A plain C FMI 2.0 Co-Simulation host for crankfmu's tests, built two ways:
 *
 * - with -DHOST_OWNS_PYTHON (and libpython): it owns the Python interpreter, started before any
 *   FMU is loaded and pointed at the environment of the `python` directive (the way a C host had
 *   to run pythonfmu's binary before crankfmu's launcher);
 * - without (the "bare" host): no Python.h, no libpython, dlopen and fmi2 calls only, as any
 *   native FMI host; the FMU's launcher finds and starts Python itself.
 *
 * It loads one or more unzipped FMUs with dlopen, wires them with a Jacobi master at a fixed step
 * and prints the requested outputs as CSV (time first, %.17g so a reader gets the exact doubles).
 * A failed fmi2ExitInitializationMode is reported on stderr ("host: fmi2ExitInitializationMode
 * returned status S for FMU K"), every instance is then freed ("host: freed"), exit code 3.
 *
 * Usage: host CONFIG_FILE            (results on stdout, FMU log messages on stderr)
 *
 * CONFIG_FILE, one directive per line ('#' starts a comment line):
 *   python PATH                 the Python executable whose environment the FMUs need (a venv's
 *                               bin/python: its pyvenv.cfg gives the site-packages)
 *   start T0 | step H | steps N | tolerance RTOL
 *   fmu NAME UNZIP_DIR MODEL_IDENTIFIER GUID      FMUs are numbered 0, 1, ... in order
 *   real FMU VR VALUE           set before initialization (parameters, inputs held constant)
 *   bool FMU VR 0|1
 *   link FROM_FMU FROM_VR TO_FMU TO_VR            a connected output -> input
 *   output FMU VR COLUMN_NAME   a recorded Real
 *
 * The sequence follows crankfmu's Jacobi master (cosim/masters/base.py and jacobi.py): connected
 * values live in buffers that start at zero; initialization sweeps the FMUs in file order
 * (n_fmus + 1 sweeps), each FMU taking its inputs from the buffers and refreshing the buffers of
 * its outputs; every step takes all inputs from the buffers at t, steps every FMU from t to
 * t + h, then refreshes the buffers.
 *
 * Build (see tests/test_importer_c.py): gcc -DHOST_OWNS_PYTHON host.c -I<python include>
 * <libpython flags> -ldl, or gcc host.c -ldl (bare)
 */
#ifdef HOST_OWNS_PYTHON
#include <Python.h>
#endif

#include <dlfcn.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h), written out so that no FMI headers
 * are needed. */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                     const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real,
                                      fmi2Boolean, fmi2Real);
typedef fmi2Status (*Simple)(fmi2Component); /* enter/exit initialization, terminate */
typedef void (*FreeInstance)(fmi2Component);
typedef fmi2Status (*GetSetReal)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*SetBoolean)(fmi2Component, const fmi2ValueReference *, size_t,
                                 const fmi2Boolean *);
typedef fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

#define MAX_ITEMS 256
#define LINE 4096

typedef struct {
    char name[256], dir[PATH_MAX], id[256], guid[256];
    void *lib;
    fmi2Component c;
    Instantiate instantiate;
    SetupExperiment setup;
    Simple enter_init, exit_init, terminate;
    FreeInstance free_instance;
    GetSetReal get_real, set_real;
    SetBoolean set_boolean;
    DoStep do_step;
} Fmu;

typedef struct { int fmu; fmi2ValueReference vr; double value; int is_bool; } Start;
typedef struct { int from, to; fmi2ValueReference from_vr, to_vr; double buffer; } Link;
typedef struct { int fmu; fmi2ValueReference vr; char name[256]; } Output;

static Fmu fmus[MAX_ITEMS];
static Start starts[MAX_ITEMS];
static Link links[MAX_ITEMS];
static Output outputs[MAX_ITEMS];
static int n_fmus, n_starts, n_links, n_outputs;
static char python[PATH_MAX];
static double t0 = 0.0, h = 1e-3, rtol = 1e-8;
static long n_steps = 1;

static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "host: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    exit(2);
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s status %d %s] ", instance ? instance : "?", (int)status,
            category ? category : "");
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

static void check(fmi2Status status, const char *call, int k) {
    if (status > fmi2Warning) die("%s returned status %d for FMU %d (%s)", call, (int)status, k,
                                  fmus[k].name);
}

static void *symbol(Fmu *f, const char *name) {
    void *s = dlsym(f->lib, name);
    if (!s) die("%s: symbol %s not found: %s", f->name, name, dlerror());
    return s;
}

static void read_config(const char *path) {
    FILE *in = fopen(path, "r");
    if (!in) die("cannot open config %s", path);
    char line[LINE], key[64];
    int lineno = 0;
    while (fgets(line, sizeof line, in)) {
        lineno++;
        if (sscanf(line, "%63s", key) != 1 || key[0] == '#') continue;
        const char *rest = strstr(line, key) + strlen(key);
        int ok = 1;
        if (!strcmp(key, "python")) ok = sscanf(rest, " %4095[^\n]", python) == 1;
        else if (!strcmp(key, "start")) ok = sscanf(rest, "%lf", &t0) == 1;
        else if (!strcmp(key, "step")) ok = sscanf(rest, "%lf", &h) == 1;
        else if (!strcmp(key, "steps")) ok = sscanf(rest, "%ld", &n_steps) == 1;
        else if (!strcmp(key, "tolerance")) ok = sscanf(rest, "%lf", &rtol) == 1;
        else if (!strcmp(key, "fmu") && n_fmus < MAX_ITEMS) {
            Fmu *f = &fmus[n_fmus++];
            ok = sscanf(rest, "%255s %4095s %255s %255s", f->name, f->dir, f->id, f->guid) == 4;
        } else if ((!strcmp(key, "real") || !strcmp(key, "bool")) && n_starts < MAX_ITEMS) {
            Start *s = &starts[n_starts++];
            s->is_bool = key[0] == 'b';
            ok = sscanf(rest, "%d %u %lf", &s->fmu, &s->vr, &s->value) == 3 && s->fmu < n_fmus;
        } else if (!strcmp(key, "link") && n_links < MAX_ITEMS) {
            Link *l = &links[n_links++];
            ok = sscanf(rest, "%d %u %d %u", &l->from, &l->from_vr, &l->to, &l->to_vr) == 4 &&
                 l->from < n_fmus && l->to < n_fmus;
        } else if (!strcmp(key, "output") && n_outputs < MAX_ITEMS) {
            Output *o = &outputs[n_outputs++];
            ok = sscanf(rest, "%d %u %255s", &o->fmu, &o->vr, o->name) == 3 && o->fmu < n_fmus;
        } else ok = 0;
        if (!ok) die("%s:%d: cannot read \"%s\" (unknown directive, bad values, FMU index not "
                     "declared yet, or more than %d items)", path, lineno, key, MAX_ITEMS);
    }
    fclose(in);
    if (!n_fmus) die("%s: no fmu line", path);
}

#ifdef HOST_OWNS_PYTHON
/* The host owns the interpreter: started before any FMU is loaded, so pythonfmu's binary finds
 * it running and neither starts nor finalizes one. program_name = the venv's python makes Python
 * read its pyvenv.cfg, so site-packages (numpy, scipy, pythonfmu) are on sys.path. */
static PyThreadState *start_python(void) {
    PyConfig config;
    PyConfig_InitPythonConfig(&config);
    if (python[0]) {
        PyStatus st = PyConfig_SetBytesString(&config, &config.program_name, python);
        if (PyStatus_Exception(st)) die("python %s: %s", python, st.err_msg);
    }
    PyStatus st = Py_InitializeFromConfig(&config);
    PyConfig_Clear(&config);
    if (PyStatus_Exception(st)) die("Python did not start: %s", st.err_msg ? st.err_msg : "?");
    /* One line on stderr saying which environment the FMUs will import from. */
    PyRun_SimpleString("import sys\n"
                       "print('host: python', sys.version.split()[0], 'prefix', sys.prefix,"
                       " file=sys.stderr, flush=True)\n");
    /* Release the GIL: pythonfmu takes it with PyGILState_Ensure in every call. */
    return PyEval_SaveThread();
}
#endif

static void load(Fmu *f, int k, const fmi2CallbackFunctions *callbacks) {
    char lib[PATH_MAX + 512], uri[PATH_MAX + 64];
    snprintf(lib, sizeof lib, "%s/binaries/linux64/%s.so", f->dir, f->id);
    f->lib = dlopen(lib, RTLD_NOW | RTLD_LOCAL);
    if (!f->lib) die("dlopen %s: %s", lib, dlerror());
    f->instantiate = (Instantiate)symbol(f, "fmi2Instantiate");
    f->setup = (SetupExperiment)symbol(f, "fmi2SetupExperiment");
    f->enter_init = (Simple)symbol(f, "fmi2EnterInitializationMode");
    f->exit_init = (Simple)symbol(f, "fmi2ExitInitializationMode");
    f->terminate = (Simple)symbol(f, "fmi2Terminate");
    f->free_instance = (FreeInstance)symbol(f, "fmi2FreeInstance");
    f->get_real = (GetSetReal)symbol(f, "fmi2GetReal");
    f->set_real = (GetSetReal)symbol(f, "fmi2SetReal");
    f->set_boolean = (SetBoolean)symbol(f, "fmi2SetBoolean");
    f->do_step = (DoStep)symbol(f, "fmi2DoStep");
    snprintf(uri, sizeof uri, "file://%s/resources", f->dir);
    f->c = f->instantiate(f->name, fmi2CoSimulation, f->guid, uri, callbacks, 0, 1);
    if (!f->c) die("fmi2Instantiate returned NULL for FMU %d (%s)", k, f->name);
}

static double get1(int k, fmi2ValueReference vr) {
    double v;
    check(fmus[k].get_real(fmus[k].c, &vr, 1, &v), "fmi2GetReal", k);
    return v;
}

/* Inputs of FMU k from the link buffers. */
static void write_inputs(int k) {
    for (int i = 0; i < n_links; i++)
        if (links[i].to == k)
            check(fmus[k].set_real(fmus[k].c, &links[i].to_vr, 1, &links[i].buffer),
                  "fmi2SetReal", k);
}

static void refresh_buffers(int k) {
    for (int i = 0; i < n_links; i++)
        if (links[i].from == k) links[i].buffer = get1(k, links[i].from_vr);
}

static void print_row(double t) {
    printf("%.17g", t);
    for (int i = 0; i < n_outputs; i++) printf(",%.17g", get1(outputs[i].fmu, outputs[i].vr));
    printf("\n");
}

int main(int argc, char **argv) {
    if (argc != 2) die("usage: %s CONFIG_FILE", argv[0]);
    read_config(argv[1]);
#ifdef HOST_OWNS_PYTHON
    PyThreadState *main_thread = start_python();
#endif
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

    for (int k = 0; k < n_fmus; k++) {
        load(&fmus[k], k, &callbacks);
        check(fmus[k].setup(fmus[k].c, 1, rtol, t0, 0, 0.0), "fmi2SetupExperiment", k);
    }
    for (int i = 0; i < n_starts; i++) {
        Start *s = &starts[i];
        Fmu *f = &fmus[s->fmu];
        if (s->is_bool) {
            fmi2Boolean b = s->value != 0.0;
            check(f->set_boolean(f->c, &s->vr, 1, &b), "fmi2SetBoolean", s->fmu);
        } else check(f->set_real(f->c, &s->vr, 1, &s->value), "fmi2SetReal", s->fmu);
    }
    for (int k = 0; k < n_fmus; k++)
        check(fmus[k].enter_init(fmus[k].c), "fmi2EnterInitializationMode", k);
    for (int sweep = 0; sweep <= n_fmus; sweep++)
        for (int k = 0; k < n_fmus; k++) { write_inputs(k); refresh_buffers(k); }
    for (int k = 0; k < n_fmus; k++) {
        fmi2Status status = fmus[k].exit_init(fmus[k].c);
        if (status > fmi2Warning) {
            fprintf(stderr, "host: fmi2ExitInitializationMode returned status %d for FMU %d\n",
                    (int)status, k);
            for (int j = 0; j < n_fmus; j++) fmus[j].free_instance(fmus[j].c);
            fprintf(stderr, "host: freed\n");
            return 3;
        }
    }
    for (int k = 0; k < n_fmus; k++) { write_inputs(k); refresh_buffers(k); }

    printf("time");
    for (int i = 0; i < n_outputs; i++) printf(",%s", outputs[i].name);
    printf("\n");
    print_row(t0);
    for (long n = 0; n < n_steps; n++) {
        double t = t0 + n * h;
        for (int k = 0; k < n_fmus; k++) write_inputs(k); /* all inputs from the buffers at t */
        for (int k = 0; k < n_fmus; k++)
            check(fmus[k].do_step(fmus[k].c, t, h, 1), "fmi2DoStep", k);
        for (int k = 0; k < n_fmus; k++) refresh_buffers(k);
        print_row(t0 + (n + 1) * h);
    }
    fflush(stdout);

    for (int k = 0; k < n_fmus; k++) {
        check(fmus[k].terminate(fmus[k].c), "fmi2Terminate", k);
        fmus[k].free_instance(fmus[k].c);
    }
#ifdef HOST_OWNS_PYTHON
    /* Finalize while the FMU libraries are still loaded (their code may run in finalizers),
     * then unload them. */
    PyEval_RestoreThread(main_thread);
    int finalized = Py_FinalizeEx();
    for (int k = 0; k < n_fmus; k++) dlclose(fmus[k].lib);
    if (finalized < 0) die("Py_FinalizeEx failed");
#else
    /* The launcher's interpreter lives until the process exits; unloading is the host's. */
    for (int k = 0; k < n_fmus; k++) dlclose(fmus[k].lib);
#endif
    return 0;
}
