/*
 * What every model behind the generic FMI layer (fmi2_cs.c) provides: the
 * life cycle, variable access by value reference, and the FMU state.  The
 * FMI layer knows no model except through these.
 *
 * Included by a model's header (model.h: JunoRover; wheel_rig.h: WheelRig)
 * after it has defined
 *   Model            the model's data: parameters, derived data, inputs,
 *                    state and outputs, and what it owns outside them;
 *   ModelState       everything an FMU state must restore, plain data (a
 *                    snapshot is a byte copy);
 *   MODEL_IDENTIFIER the FMU's model identifier, for messages.
 * Which model an FMU wraps is chosen by the build (CMakeLists.txt: the
 * generated juno_guid.h names the model's header and variable table).
 * The variable accessors are generated from the model's variable table
 * (model_vars.c).
 */
#ifndef JUNO_MODEL_HOOKS_H
#define JUNO_MODEL_HOOKS_H

#include <stddef.h>

/* The start values of every parameter and input (from the variable table). */
void model_set_defaults(Model *m);

/* A fresh model: what m owned freed (m zeroed or a model already), then
 * the start values. */
void model_reset(Model *m);

/* After the parameters are set: checks them, prepares the model and puts
 * it in its initial state (the rover and the rig: static equilibrium).
 * Returns 0, or -1 with a message in err. */
int model_initialize(Model *m, char *err, size_t errlen);

/* Advances from the model's time by h_comm (s) using internal substeps.
 * Returns 0, or -1 with a message in err (bad input, diverging state). */
int model_do_step(Model *m, double h_comm, char *err, size_t errlen);

/* Frees what the model owns (files loaded, string values) and leaves
 * them empty. */
void model_free(Model *m);

/* Variable access by value reference (model_vars.c, from the table).
 * Return 0, or -1 for an unknown reference. */
int model_get_real(const Model *m, unsigned vr, double *value);
int model_set_real(Model *m, unsigned vr, double value);
int model_get_int(const Model *m, unsigned vr, int *value);
int model_set_int(Model *m, unsigned vr, int value);
/* kind of a variable: 'P' parameter, 'C' calculated parameter, 'I' input,
 * 'O' output, 0 unknown; and its name and inclusive range. */
int model_var_kind(unsigned vr, char type);
const char *model_var_name(unsigned vr, char type);
void model_real_range(unsigned vr, double *min, double *max);
void model_int_range(unsigned vr, int *min, int *max);
int model_is_string_var(unsigned vr);
/* A String variable's value ("" when unset), or NULL for an unknown
 * reference. */
const char *model_get_string(const Model *m, unsigned vr);
/* Sets a String variable to a copy of value.  Returns 0, or -1 for an
 * unknown reference or when out of memory (then the value is unchanged). */
int model_set_string(Model *m, unsigned vr, const char *value);

/* A relative file name among the String variables that names no file
 * here is looked up in the FMU's resources folder (resource_dir, a local
 * path; NULL: none); if a file is there, initialisation opens that path
 * (Model.resolved), else the name as set.  The variables keep their
 * values. */
void model_resolve_resources(Model *m, const char *resource_dir);

/* The simulation time (s). */
double model_get_time(const Model *m);
void model_set_time(Model *m, double time);

/* 0 if a communication step of h (s) is affordable, else -1 with why (a
 * clause that follows "communicationStepSize = <h> s "). */
int model_check_step_size(const Model *m, double h, char *why, size_t n);

/* One line on the initialised model for the log. */
void model_describe(const Model *m, char *buf, size_t n);

void model_get_state(const Model *m, ModelState *st);
void model_set_state(Model *m, const ModelState *st);

/* Called by the accessors (model_vars.c) after they write anything but an
 * input or the time: a parameter, a String variable, a whole state.  A
 * model that keeps work from one step for the next (the rover: its
 * end-of-step evaluation) forgets it here; the rig keeps none. */
void model_changed(Model *m);

/* A stepping state set into this instance (an initialised one) must have been taken where what
 * initialisation loads outside ModelState (the rover: its terrain grid) is the same.  Returns
 * NULL, or what differs, written into why. */
const char *model_state_foreign(const Model *m, const ModelState *st, char *why, size_t n);
/* A state from elsewhere (deserialised: a tool's storage, a crafted file)
 * must hold values the model itself could have had: parameters and inputs
 * within their declared ranges, and when it is to be stepped (stepping)
 * a finite, bounded integrator state.  Returns NULL, or what is wrong,
 * written into why. */
const char *model_state_invalid(const ModelState *st, int stepping, char *why, size_t n);

#endif
