/* crankfmu FMU launcher, the part both FMI versions share: finding and starting Python, the
 * pre-flight check, loading pythonfmu's binary. Included by launcher.c (FMI 2.0, pythonfmu) and
 * launcher3.c (FMI 3.0, pythonfmu3); see launcher.c for what the launcher does and why.
 *
 * Which Python (the search, in this order; the first suitable one is used):
 *   1. an interpreter already running in the host process (fmpy, libcosimpy, ecospy, a C host
 *      that owns one): used as it is;
 *   2. CRANKFMU_PYTHON, when set: a python executable, or an environment / installation folder
 *      (its bin/python<version>, bin/python3, bin/python); the only candidate then;
 *   3. the builder's environment, when the build recorded it (resources/crankfmu_launcher.txt,
 *      `python =`) and it is still there;
 *   4. on PATH, directory by directory: python<version>, python3, python.
 * A candidate is suitable when it runs, is Python <version> (the one pythonfmu's binary was
 * built for), has a shared libpython and imports the packages the runtime needs; each is asked
 * by running it once (`python -c <probe> numpy scipy`), before anything is loaded here. When
 * none is, the instantiate call fails and the message lists every candidate with the reason.
 * CRANKFMU_LIBPYTHON names libpython when the candidate's own is not the one to load.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <wchar.h>

#define EXPORT __attribute__((visibility("default")))
#define TEXT 4096

/* ---- what the build records (resources/crankfmu_launcher.txt) ----------------------------- */
typedef struct {
    char model[256];        /* modelIdentifier: pythonfmu's binary is <model>_<suffix>.so */
    char python[TEXT];      /* the builder's python executable ("" in a portable build) */
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

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static PyApi py;
static int py_ready;
static int py_started_here;        /* this launcher started the interpreter */
static void *real;                 /* pythonfmu's binary: dlopen handle, NULL until loaded */
static void (*real_finalize)(void);

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

/* Append to a bounded text: the list of what the search tried. */
static void append(char *text, size_t size, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void append(char *text, size_t size, const char *fmt, ...) {
    size_t n = strlen(text);
    if (n + 1 >= size) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text + n, size - n, fmt, ap);
    va_end(ap);
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
    "beside it), or put such a python on PATH; see the FMU's documentation/index.html, "          \
    "\"Using the FMUs in other tools\"."

/* ---- the search ------------------------------------------------------------------------------ */
/* What a candidate says about itself: run once with the packages as arguments; prints its
 * version, its sys.executable, its shared libpython ("" if none) and the packages it cannot
 * import with the reason ("" if none). The probe imports them (in its own process, once per
 * candidate, in a host without Python only), so that a candidate whose package is there but
 * broken is passed over for the next; the pre-flight in the chosen interpreter only looks them
 * up. */
static const char PROBE[] =
    "import os, sys, sysconfig\n"
    "c = sysconfig.get_config_var\n"
    "lib = ''\n"
    "for d in (c('LIBDIR'), c('LIBPL')):\n"
    "    for n in (c('INSTSONAME'), c('LDLIBRARY')):\n"
    "        if not lib and d and n and '.so' in n and os.path.isfile(os.path.join(d, n)):\n"
    "            lib = os.path.join(d, n)\n"
    "missing = []\n"
    "for name in sys.argv[1:]:\n"
    "    try:\n"
    "        __import__(name)\n"
    "    except Exception as err:\n"
    "        missing.append(f'{name} ({type(err).__name__}: {err})')\n"
    "print('%d.%d' % sys.version_info[:2], sys.executable, lib, '; '.join(missing), sep='\\n')\n";

typedef struct {
    char executable[TEXT];  /* its sys.executable: the program name that finds its packages */
    char libpython[TEXT];
} Found;

/* Run `exe -c PROBE <requires>`; its output into `out`. 0 when it did not run to success. */
static int run_probe(const char *exe, const Config *cfg, char *out, size_t size) {
    char words[TEXT];
    char *argv[64];
    int argc = 0;
    snprintf(words, sizeof words, "%s", cfg->requires);
    argv[argc++] = (char *)exe;
    argv[argc++] = "-c";
    argv[argc++] = (char *)PROBE;
    for (char *save = NULL, *w = strtok_r(words, " ", &save); w && argc < 63;
         w = strtok_r(NULL, " ", &save))
        argv[argc++] = w;
    argv[argc] = NULL;
    int fd[2];
    if (pipe(fd)) return 0;
    pid_t pid = fork();
    if (pid < 0) { close(fd[0]); close(fd[1]); return 0; }
    if (pid == 0) {  /* only async-signal-safe calls until execv */
        int quiet = open("/dev/null", O_WRONLY);
        dup2(fd[1], 1);
        if (quiet >= 0) dup2(quiet, 2);
        close(fd[0]);
        close(fd[1]);
        execv(exe, argv);
        _exit(127);
    }
    close(fd[1]);
    size_t n = 0;
    ssize_t got;
    while ((got = read(fd[0], out + n, size - 1 - n)) > 0 && n + 1 < size) n += (size_t)got;
    out[n] = 0;
    close(fd[0]);
    int status = 0;
    while (waitpid(pid, &status, 0) < 0) {}
    return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

/* Is `exe` a suitable Python? On success `found` is filled; else `why` says why not. */
static int suitable(const char *exe, const Config *cfg, Found *found, char *why, size_t size) {
    char out[4 * TEXT], *line[4] = {0};
    if (!is_file(exe) || access(exe, X_OK)) {
        snprintf(why, size, "no python executable there");
        return 0;
    }
    if (!run_probe(exe, cfg, out, sizeof out)) {
        snprintf(why, size, "does not run as Python (its probe failed)");
        return 0;
    }
    char *p = out;
    for (int i = 0; i < 4; i++) {  /* four lines; an empty one is a value too */
        char *nl = strchr(p, '\n');
        if (!nl) break;
        *nl = 0;
        line[i] = p;
        p = nl + 1;
    }
    if (!line[3]) {
        snprintf(why, size, "gave no answer to the probe");
        return 0;
    }
    if (strcmp(line[0], cfg->version)) {
        snprintf(why, size, "is Python %s, not %s (pythonfmu's binary is built for %s)",
                 line[0], cfg->version, cfg->version);
        return 0;
    }
    if (line[3][0]) {
        snprintf(why, size, "Python package(s) missing: %s. The FMU runs in the Python at %s, "
                 "which cannot import them", line[3], line[1]);
        return 0;
    }
    const char *lib = getenv("CRANKFMU_LIBPYTHON");
    if (lib && lib[0]) snprintf(found->libpython, sizeof found->libpython, "%s", lib);
    else if (line[2][0]) snprintf(found->libpython, sizeof found->libpython, "%s", line[2]);
    else {
        snprintf(why, size, "has no shared libpython%s (a static build)", cfg->version);
        return 0;
    }
    snprintf(found->executable, sizeof found->executable, "%s", line[1]);
    return 1;
}

/* CRANKFMU_PYTHON as an executable: the file itself, or <folder>/bin/python<version>,
 * <folder>/bin/python3, <folder>/bin/python for an environment or installation folder. */
static void override_python(const char *given, const Config *cfg, char *out, size_t size) {
    if (!is_dir(given)) { snprintf(out, size, "%s", given); return; }
    const char *names[] = {"python", "python3", NULL};
    snprintf(out, size, "%s/bin/python%s", given, cfg->version);
    for (int i = 0; names[i] && !is_file(out); i++)
        snprintf(out, size, "%s/bin/%s", given, names[i]);
}

/* The search (see the top of this file); `tried` collects each candidate and the verdict. */
static int find_python(const Config *cfg, Found *found, char *error, size_t size) {
    char exe[TEXT], why[2 * TEXT], tried[6 * TEXT] = "";
    const char *given = getenv("CRANKFMU_PYTHON");
    if (given && given[0]) {
        override_python(given, cfg, exe, sizeof exe);
        if (suitable(exe, cfg, found, why, sizeof why)) return 1;
        snprintf(error, size, "CRANKFMU_PYTHON gives %s: %s. " HOW_TO_POINT, exe, why,
                 cfg->version, cfg->requires, cfg->version);
        return 0;
    }
    if (cfg->python[0]) {
        if (suitable(cfg->python, cfg, found, why, sizeof why)) return 1;
        append(tried, sizeof tried, "the builder's environment %s: %s; ", cfg->python, why);
    } else
        append(tried, sizeof tried, "(a portable build: no builder's environment recorded); ");
    const char *path = getenv("PATH");
    char dirs[2 * TEXT], names[3][64];
    snprintf(dirs, sizeof dirs, "%s", path ? path : "");
    snprintf(names[0], sizeof names[0], "python%s", cfg->version);
    snprintf(names[1], sizeof names[1], "python3");
    snprintf(names[2], sizeof names[2], "python");
    int any = 0;
    for (char *save = NULL, *dir = strtok_r(dirs, ":", &save); dir;
         dir = strtok_r(NULL, ":", &save)) {
        for (int i = 0; i < 3; i++) {
            snprintf(exe, sizeof exe, "%s/%s", dir[0] ? dir : ".", names[i]);
            if (!is_file(exe)) continue;
            any = 1;
            if (suitable(exe, cfg, found, why, sizeof why)) return 1;
            append(tried, sizeof tried, "%s: %s; ", exe, why);
        }
    }
    if (!any)
        append(tried, sizeof tried, "PATH (%s) holds no python%s, python3 or python; ",
               path ? path : "unset", cfg->version);
    snprintf(error, size, "no suitable Python %s found (tried: %s). " HOW_TO_POINT,
             cfg->version, tried, cfg->version, cfg->requires, cfg->version);
    return 0;
}

/* Make sure an initialized interpreter runs in this process; start one if needed. */
static int ensure_python(const Config *cfg, char *error, size_t size) {
    if (py_ready) return 1;
    Found found = {"", ""};
    void *lib = dlopen(NULL, RTLD_NOW);  /* the process: a Python host or a host linking it */
    int in_process = lib && dlsym(lib, "Py_IsInitialized");
    if (in_process) {
        if (!bind_python(lib, "this process", cfg->version, error, size)) return 0;
        if (py.IsInitialized()) { py_ready = 1; return 1; }
    }
    if (!find_python(cfg, &found, error, size)) return 0;
    if (!in_process) {
        lib = dlopen(found.libpython, RTLD_NOW | RTLD_GLOBAL);
        if (!lib) {
            snprintf(error, size, "Python %s at %s: its libpython %s does not load: %s. "
                     HOW_TO_POINT, cfg->version, found.executable, found.libpython, dlerror(),
                     cfg->version, cfg->requires, cfg->version);
            return 0;
        }
        if (!bind_python(lib, found.libpython, cfg->version, error, size)) return 0;
    }
    if (!py.IsInitialized()) {
        /* The program name makes Python find the environment: a venv's pyvenv.cfg beside it
         * adds the venv's site-packages; an installation's prefix is found from it. */
        wchar_t *program = py.DecodeLocale(found.executable, NULL);
        if (program) py.SetProgramName(program); /* kept: Python uses it until exit */
        py.InitializeEx(0);                       /* 0: no signal handlers in the host */
        py.SaveThread();                          /* release the GIL; pythonfmu takes it */
        py_started_here = 1;
    }
    py_ready = 1;
    return 1;
}

/* Find the packages the runtime needs (find_spec: found, not imported, so a run that does not
 * use scipy does not pay for its import); on failure write what is missing into `error`. */
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

/* pythonfmu's binary <model>_<suffix>.so beside this launcher (else in <resources>/../<dir>):
 * loaded once, pinned, with its exit handler registered. */
static int load_real(const Config *cfg, const char *resources, const char *suffix,
                     const char *platform_dir, char *error, size_t size) {
    if (real) return 1;
    char dir[TEXT], path[2 * TEXT];
    if (own_dir(dir, sizeof dir)) snprintf(path, sizeof path, "%s/%s_%s.so", dir, cfg->model,
                                           suffix);
    if (!own_dir(dir, sizeof dir) || !is_file(path))
        snprintf(path, sizeof path, "%s/../binaries/%s/%s_%s.so", resources, platform_dir,
                 cfg->model, suffix);
    real = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    if (!real) {
        snprintf(error, size, "cannot load pythonfmu's binary: %s", dlerror());
        return 0;
    }
    *(void **)&real_finalize = dlsym(real, "finalizePythonInterpreter");
    /* Registered after the binary's static constructors: runs before its static destructors. */
    atexit(release_at_exit);
    /* Pin this launcher too: the exit handler above lives in it. */
    Dl_info info;
    if (dladdr((void *)&load_real, &info) && info.dli_fname)
        dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
    return 1;
}

/* "file:///a%20b/resources" -> "/a b/resources"; a plain path (FMI 3.0) stays, without the
 * trailing separator */
static void uri_to_path(const char *uri, char *out, size_t size) {
    const char *p = uri ? uri : "";
    int is_uri = !strncmp(p, "file:", 5);
    if (!strncmp(p, "file://", 7)) p += 7;
    if (!strncmp(p, "localhost/", 10)) p += 9;
    size_t n = 0;
    for (; *p && n + 1 < size; p++) {
        unsigned int byte;
        if (is_uri && p[0] == '%' && sscanf(p + 1, "%2x", &byte) == 1) {
            out[n++] = (char)byte;
            p += 2;
        } else out[n++] = *p;
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

/* What an instance passes on to the host's logger: errors always; the other messages when
 * logging is on, of every category or of those the host named (fmiXSetDebugLogging). */
typedef struct {
    int on;
    size_t n;
    char **categories;
} LogFilter;

static int log_wanted(const LogFilter *f, int is_error, const char *category) {
    if (is_error) return 1;
    if (!f->on) return 0;
    if (f->n == 0) return 1;
    for (size_t i = 0; i < f->n; i++)
        if ((category && !strcmp(category, f->categories[i])) ||
            !strcmp(f->categories[i], "logAll"))
            return 1;
    return 0;
}

static void clear_log_filter(LogFilter *f) {
    for (size_t i = 0; i < f->n; i++) free(f->categories[i]);
    free(f->categories);
    f->categories = NULL;
    f->n = 0;
}

/* 0 when out of memory */
static int set_log_filter(LogFilter *f, int on, size_t n, const char *const categories[]) {
    clear_log_filter(f);
    f->on = on;
    if (on && n) {
        f->categories = calloc(n, sizeof *f->categories);
        if (!f->categories) return 0;
        for (size_t i = 0; i < n; i++) f->categories[i] = copy(categories[i]);
        f->n = n;
    }
    return 1;
}

/* Everything before the first instance: configuration, Python, pre-flight, pythonfmu's binary. */
static int prepare(const char *resources_dir, const char *suffix, const char *platform_dir,
                   Config *cfg, char *error, size_t size) {
    pthread_mutex_lock(&lock);
    int ok = read_config(resources_dir, cfg, error, size) &&
             ensure_python(cfg, error, size) &&
             preflight(cfg, error, size) &&
             load_real(cfg, resources_dir, suffix, platform_dir, error, size);
    pthread_mutex_unlock(&lock);
    return ok;
}
