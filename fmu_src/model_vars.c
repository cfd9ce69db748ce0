/* Accessors by value reference, generated from modelDescription/variables.h. */
#include <math.h>
#include <stddef.h>
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
