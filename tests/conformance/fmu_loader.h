/*
 * Loading the JunoRover FMU as an importer does: the staged FMU folder
 * (build/fmu: modelDescription.xml, binaries/<platform>/JunoRover.<ext>),
 * the GUID and the variables read from the modelDescription.xml, the
 * binary opened with dlopen (LoadLibrary on Windows) and every FMI 2.0
 * Co-Simulation function looked up by name.  Header-only, for the
 * conformance and parallel drivers.
 */
#ifndef JUNO_FMU_LOADER_H
#define JUNO_FMU_LOADER_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(_WIN32)
#include <windows.h>
#define FMU_PLATFORM "win64"
#define FMU_SUFFIX ".dll"
#else
#include <dlfcn.h>
#define FMU_PLATFORM "linux64"
#define FMU_SUFFIX ".so"
#endif

#include "fmi2.h"

typedef struct {
    const char *(*GetTypesPlatform)(void);
    const char *(*GetVersion)(void);
    fmi2Status (*SetDebugLogging)(fmi2Component, fmi2Boolean, size_t, const fmi2String[]);
    fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions *,
                                 fmi2Boolean, fmi2Boolean);
    void (*FreeInstance)(fmi2Component);
    fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*EnterInitializationMode)(fmi2Component);
    fmi2Status (*ExitInitializationMode)(fmi2Component);
    fmi2Status (*Terminate)(fmi2Component);
    fmi2Status (*Reset)(fmi2Component);
    fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
    fmi2Status (*GetInteger)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]);
    fmi2Status (*GetBoolean)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Boolean[]);
    fmi2Status (*GetString)(fmi2Component, const fmi2ValueReference[], size_t, fmi2String[]);
    fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
    fmi2Status (*SetInteger)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[]);
    fmi2Status (*SetBoolean)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Boolean[]);
    fmi2Status (*SetString)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2String[]);
    fmi2Status (*GetFMUstate)(fmi2Component, fmi2FMUstate *);
    fmi2Status (*SetFMUstate)(fmi2Component, fmi2FMUstate);
    fmi2Status (*FreeFMUstate)(fmi2Component, fmi2FMUstate *);
    fmi2Status (*SerializedFMUstateSize)(fmi2Component, fmi2FMUstate, size_t *);
    fmi2Status (*SerializeFMUstate)(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t);
    fmi2Status (*DeSerializeFMUstate)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate *);
    fmi2Status (*GetDirectionalDerivative)(fmi2Component, const fmi2ValueReference[], size_t,
                                           const fmi2ValueReference[], size_t, const fmi2Real[], fmi2Real[]);
    fmi2Status (*SetRealInputDerivatives)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                          const fmi2Real[]);
    fmi2Status (*GetRealOutputDerivatives)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                           fmi2Real[]);
    fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    fmi2Status (*CancelStep)(fmi2Component);
    fmi2Status (*GetStatus)(fmi2Component, const fmi2StatusKind, fmi2Status *);
    fmi2Status (*GetRealStatus)(fmi2Component, const fmi2StatusKind, fmi2Real *);
    fmi2Status (*GetIntegerStatus)(fmi2Component, const fmi2StatusKind, fmi2Integer *);
    fmi2Status (*GetBooleanStatus)(fmi2Component, const fmi2StatusKind, fmi2Boolean *);
    fmi2Status (*GetStringStatus)(fmi2Component, const fmi2StatusKind, fmi2String *);
} Fmi;

/* The 34 functions of an FMI 2.0 Co-Simulation FMU (25 common + 9 Co-Simulation), in Fmi's order. */
static const char *const fmi_function_names[] = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
    "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
    "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
    "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus"};
#define FMI_NUM_FUNCTIONS (sizeof fmi_function_names / sizeof fmi_function_names[0])
_Static_assert(sizeof(Fmi) == 34 * sizeof(void (*)(void)), "Fmi must hold the 34 FMI 2.0 CS functions");

typedef struct {
    char name[96];
    unsigned vr;
    char type;          /* 'r', 'i', 's', 'b' */
    char causality;     /* 'p' parameter, 'c' calculatedParameter, 'i' input, 'o' output, '?' */
    int has_min, has_max;
    double min, max;
} FmuVar;

typedef struct {
    char guid[128];
    char binary[4096];
    FmuVar *vars;
    int nvars;
    Fmi fmi;
#if defined(_WIN32)
    HMODULE handle;
#else
    void *handle;
#endif
} Fmu;

static inline char *loader_read_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    size_t cap = 1 << 16, n = 0;
    char *buf = (char *)malloc(cap + 1);
    while (buf) {
        size_t got = fread(buf + n, 1, cap - n, f);
        n += got;
        if (n < cap) break;
        char *bigger = (char *)realloc(buf, 2 * cap + 1);
        if (!bigger) { free(buf); buf = NULL; break; }
        buf = bigger;
        cap *= 2;
    }
    fclose(f);
    if (buf) buf[n] = '\0';
    return buf;
}

/* Value of attribute key="..." in [tag, end), or 0. */
static inline int loader_attr(const char *tag, const char *end, const char *key, char *out, size_t n)
{
    char pat[64];
    snprintf(pat, sizeof pat, " %s=\"", key);
    size_t plen = strlen(pat);
    for (const char *p = tag; p + plen < end; ++p) {
        if (memcmp(p, pat, plen) != 0) continue;
        const char *v = p + plen, *q = v;
        while (q < end && *q != '"') ++q;
        size_t len = (size_t)(q - v) < n - 1 ? (size_t)(q - v) : n - 1;
        memcpy(out, v, len);
        out[len] = '\0';
        return 1;
    }
    return 0;
}

/* Reads dir/modelDescription.xml and opens dir/binaries/<platform>/JunoRover<ext>.
 * Returns 0, or -1 with a message on stderr. */
static inline int fmu_load(Fmu *fmu, const char *dir)
{
    memset(fmu, 0, sizeof *fmu);
    char path[4096];
    snprintf(path, sizeof path, "%s/modelDescription.xml", dir);
    char *xml = loader_read_file(path);
    if (!xml) { fprintf(stderr, "cannot read %s\n", path); return -1; }
    const char *root = strstr(xml, "<fmiModelDescription");
    const char *root_end = root ? strchr(root, '>') : NULL;
    if (!root_end || !loader_attr(root, root_end, "guid", fmu->guid, sizeof fmu->guid)) {
        fprintf(stderr, "%s: no guid\n", path);
        free(xml);
        return -1;
    }
    int cap = 64;
    fmu->vars = (FmuVar *)calloc((size_t)cap, sizeof *fmu->vars);
    for (const char *p = strstr(xml, "<ScalarVariable "); p && fmu->vars; p = strstr(p + 1, "<ScalarVariable ")) {
        const char *tag_end = strchr(p, '>');
        const char *end = strstr(p, "</ScalarVariable>");
        if (!tag_end || !end) break;
        if (fmu->nvars == cap) {
            FmuVar *bigger = (FmuVar *)realloc(fmu->vars, 2 * (size_t)cap * sizeof *bigger);
            if (!bigger) { free(fmu->vars); fmu->vars = NULL; break; }
            fmu->vars = bigger;
            cap *= 2;
        }
        FmuVar *v = &fmu->vars[fmu->nvars];
        memset(v, 0, sizeof *v);
        char buf[96];
        loader_attr(p, tag_end, "name", v->name, sizeof v->name);
        if (loader_attr(p, tag_end, "valueReference", buf, sizeof buf)) v->vr = (unsigned)strtoul(buf, NULL, 10);
        v->causality = '?';
        if (loader_attr(p, tag_end, "causality", buf, sizeof buf)) {
            if (!strcmp(buf, "parameter")) v->causality = 'p';
            else if (!strcmp(buf, "calculatedParameter")) v->causality = 'c';
            else if (!strcmp(buf, "input")) v->causality = 'i';
            else if (!strcmp(buf, "output")) v->causality = 'o';
        }
        const char *t = tag_end + 1;
        while (t < end && *t != '<') ++t;
        const char *t_end = strchr(t, '>');
        if (!strncmp(t, "<Real", 5)) v->type = 'r';
        else if (!strncmp(t, "<Integer", 8)) v->type = 'i';
        else if (!strncmp(t, "<String", 7)) v->type = 's';
        else if (!strncmp(t, "<Boolean", 8)) v->type = 'b';
        if (t_end && loader_attr(t, t_end, "min", buf, sizeof buf)) v->has_min = 1, v->min = strtod(buf, NULL);
        if (t_end && loader_attr(t, t_end, "max", buf, sizeof buf)) v->has_max = 1, v->max = strtod(buf, NULL);
        fmu->nvars++;
    }
    free(xml);
    if (!fmu->vars || fmu->nvars == 0) { fprintf(stderr, "%s: no variables\n", path); return -1; }

    snprintf(fmu->binary, sizeof fmu->binary, "%s/binaries/%s/JunoRover%s", dir, FMU_PLATFORM, FMU_SUFFIX);
#if defined(_WIN32)
    fmu->handle = LoadLibraryA(fmu->binary);
#else
    fmu->handle = dlopen(fmu->binary, RTLD_NOW | RTLD_LOCAL);
#endif
    if (!fmu->handle) {
#if defined(_WIN32)
        fprintf(stderr, "cannot load %s (error %lu)\n", fmu->binary, (unsigned long)GetLastError());
#else
        fprintf(stderr, "cannot load %s: %s\n", fmu->binary, dlerror());
#endif
        return -1;
    }
    void (**slots)(void) = (void (**)(void))&fmu->fmi;   /* Fmi is an array of function pointers */
    for (size_t i = 0; i < FMI_NUM_FUNCTIONS; ++i) {
#if defined(_WIN32)
        FARPROC sym = GetProcAddress(fmu->handle, fmi_function_names[i]);
#else
        void *sym = dlsym(fmu->handle, fmi_function_names[i]);
#endif
        if (!sym) { fprintf(stderr, "%s does not export %s\n", fmu->binary, fmi_function_names[i]); return -1; }
        memcpy(&slots[i], &sym, sizeof sym);
    }
    return 0;
}

static inline void fmu_unload(Fmu *fmu)
{
    if (fmu->handle) {
#if defined(_WIN32)
        FreeLibrary(fmu->handle);
#else
        dlclose(fmu->handle);
#endif
    }
    free(fmu->vars);
    memset(fmu, 0, sizeof *fmu);
}

static inline const FmuVar *fmu_var(const Fmu *fmu, const char *name)
{
    for (int i = 0; i < fmu->nvars; ++i)
        if (!strcmp(fmu->vars[i].name, name)) return &fmu->vars[i];
    fprintf(stderr, "the model description has no variable %s\n", name);
    exit(2);
}

/* file:// URI of a local absolute path, with everything but unreserved
 * characters and '/' percent-encoded (so spaces become %20). */
static inline void path_to_uri(const char *path, char *out, size_t n)
{
    static const char hex[] = "0123456789ABCDEF";
    size_t j = 0;
    const char *prefix = "file://";
#if defined(_WIN32)
    prefix = "file:///";
#endif
    for (const char *p = prefix; *p && j + 1 < n; ++p) out[j++] = *p;
    for (const unsigned char *p = (const unsigned char *)path; *p && j + 4 < n; ++p) {
        unsigned char ch = *p;
#if defined(_WIN32)
        if (ch == '\\') ch = '/';
#endif
        if ((ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '/' ||
            ch == '-' || ch == '_' || ch == '.' || ch == '~' || ch == ':') {
            out[j++] = (char)ch;
        } else {
            out[j++] = '%';
            out[j++] = hex[ch >> 4];
            out[j++] = hex[ch & 15];
        }
    }
    out[j] = '\0';
}

#endif
