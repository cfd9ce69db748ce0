/* Accessors by value reference, generated from modelDescription/variables.h,
 * and what the FMI layer needs of the variables: string values, resource
 * paths, the checks of a state from elsewhere. */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 200809L   /* stat under -std=c11 */
#endif
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model.h"

#define KIND_PARAM  'P'
#define KIND_CALC   'C'
#define KIND_INPUT  'I'
#define KIND_OUTPUT 'O'
#define PARAM  KIND_PARAM
#define CALC   KIND_CALC
#define INPUT  KIND_INPUT
#define OUTPUT KIND_OUTPUT

#include "variables.h"

int model_get_real(const Model *m, unsigned vr, double *value)
{
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) case vr_: *value = m->field; return 0;
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return -1;
    }
}

int model_set_real(Model *m, unsigned vr, double value)
{
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) case vr_: m->field = value; return 0;
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return -1;
    }
}

int model_get_int(const Model *m, unsigned vr, int *value)
{
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc) case vr_: *value = m->field; return 0;
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return -1;
    }
}

int model_set_int(Model *m, unsigned vr, int value)
{
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc) case vr_: m->field = value; return 0;
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return -1;
    }
}

/* type: 'r' real, 'i' integer, 's' string. */
int model_var_kind(unsigned vr, char type)
{
    switch (type) {
    case 'r':
        switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) case vr_: return kind;
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc)
        JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
        default: return 0;
        }
    case 'i':
        switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc) case vr_: return kind;
#define STR(vr_, name, kind, start, field, desc)
        JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
        default: return 0;
        }
    case 's':
        switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc) case vr_: return kind;
        JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
        default: return 0;
        }
    default:
        return 0;
    }
}

const char *model_var_name(unsigned vr, char type)
{
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) if (type == 'r' && vr == vr_) return name;
#define INT(vr_, name, kind, start, lo, hi, field, desc) if (type == 'i' && vr == vr_) return name;
#define STR(vr_, name, kind, start, field, desc) if (type == 's' && vr == vr_) return name;
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    return "?";
}

void model_real_range(unsigned vr, double *min, double *max)
{
    *min = -HUGE_VAL;
    *max = HUGE_VAL;
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) case vr_: *min = lo; *max = hi; return;
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return;
    }
}

void model_int_range(unsigned vr, int *min, int *max)
{
    *min = -2147483647;
    *max = 2147483647;
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc) case vr_: *min = lo; *max = hi; return;
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return;
    }
}

/* Start values: the single place defaults come from. */
void model_set_defaults(Model *m)
{
    m->eval_valid = 0;
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc) if (kind != OUTPUT && kind != CALC) m->field = start;
#define INT(vr_, name, kind, start, lo, hi, field, desc) m->field = start;
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
}

int model_is_string_var(unsigned vr)
{
    return model_var_kind(vr, 's') != 0;
}

const char *model_get_string(const Model *m, unsigned vr)
{
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc) case vr_: return m->field ? m->field : "";
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return NULL;
    }
}

/* Replaces *field by a malloc'ed copy of value; -1 if out of memory. */
static int set_owned_string(char **field, const char *value)
{
    const size_t n = strlen(value) + 1;
    char *copy = (char *)malloc(n);
    if (!copy) return -1;
    memcpy(copy, value, n);
    free(*field);
    *field = copy;
    return 0;
}

int model_set_string(Model *m, unsigned vr, const char *value)
{
    if (!value) return -1;
    switch (vr) {
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc) case vr_: return set_owned_string(&m->field, value);
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    default: return -1;
    }
}

/* A relative path that does not exist here, looked up in the resources:
 * stat, not fopen, decides, as opening a FIFO would wait for a writer. */
static void resolve_in(char **field, const char *resource_dir)
{
    struct stat st;
    const char *name = *field;
    if (!name || !name[0] || name[0] == '/' || !resource_dir || stat(name, &st) == 0) return;
    const size_t n = strlen(resource_dir) + strlen(name) + 2;
    char *resolved = (char *)malloc(n);
    if (!resolved) return;
    snprintf(resolved, n, "%s/%s", resource_dir, name);
    if (stat(resolved, &st) == 0) {
        free(*field);
        *field = resolved;
    } else {
        free(resolved);
    }
}

void model_resolve_resources(Model *m, const char *resource_dir)
{
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)
#define INT(vr_, name, kind, start, lo, hi, field, desc)
#define STR(vr_, name, kind, start, field, desc) resolve_in(&m->field, resource_dir);
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
}

void model_get_state(const Model *m, ModelState *st)
{
    st->p = m->p;
    st->d = m->d;
    st->in = m->in;
    st->s = m->s;
    st->out = m->out;
}

void model_set_state(Model *m, const ModelState *st)
{
    m->p = st->p;
    m->d = st->d;
    m->in = st->in;
    m->s = st->s;
    m->out = st->out;
}

/* Parameters and inputs are checked against the variable table as
 * fmi2SetReal/fmi2SetInteger would check them. */
const char *model_state_invalid(const ModelState *st, int stepping, char *why, size_t n)
{
    Model tmp;
    const Model *m = &tmp;
    memset(&tmp, 0, sizeof tmp);
    tmp.p = st->p;
    tmp.in = st->in;
#define REAL(vr_, name, kind, unit, start, lo, hi, field, desc)                                                  \
    if ((kind == PARAM || kind == INPUT) && !(isfinite(m->field) && m->field >= (lo) && m->field <= (hi))) {    \
        snprintf(why, n, "'%s' = %g is outside its range [%g, %g]", name, m->field, (double)(lo), (double)(hi)); \
        return why;                                                                                            \
    }
#define INT(vr_, name, kind, start, lo, hi, field, desc)                                               \
    if (kind == PARAM && !(m->field >= (lo) && m->field <= (hi))) {                                    \
        snprintf(why, n, "'%s' = %d is outside its range [%d, %d]", name, m->field, (int)(lo), (int)(hi)); \
        return why;                                                                                    \
    }
#define STR(vr_, name, kind, start, field, desc)
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    if (stepping) {
        /* State is plain data made of doubles (model.h); none may be NaN, infinite or absurd */
        const unsigned char *bytes = (const unsigned char *)&st->s;
        for (size_t i = 0; i + sizeof(double) <= sizeof st->s; i += sizeof(double)) {
            double v;
            memcpy(&v, bytes + i, sizeof v);
            if (!(fabs(v) <= 1e15)) {
                snprintf(why, n, "the integrator state holds %g at byte %zu", v, i);
                return why;
            }
        }
    }
    return NULL;
}
