/*
 * libFuzzer target: the FMU state deserializer of either FMU, built once per
 * model from this file: fuzz_state (JunoRover) and fuzz_rig_state (WheelRig,
 * -DJUNO_FUZZ_RIG).  Each input becomes a serialized FMU state that goes
 * through fmi2DeSerializeFMUstate, then (if accepted) fmi2SetFMUstate, an
 * fmi2DoStep and fmi2GetReal of every output.  Nothing may crash, hang or
 * trip the sanitizers; a refused state must be explained in the log.
 *
 * The first input byte selects how the rest is used:
 *   0  the bytes themselves are the serialized state (size, magic, version
 *      and checksum checks);
 *   1  the bytes are XORed into a valid serialized state at an offset given
 *      by the next two bytes, and the checksum is recomputed, so that the
 *      payload itself is fuzzed (what a tool or a bit flip in memory could
 *      hand back);
 *   2  like 1, but whole doubles at 8-byte aligned offsets are replaced by
 *      special values (NaN, +-Inf, 0, -1, +-1e300, tiny).
 *
 *   fuzz_state tests/fuzz/corpus_state -max_total_time=20
 *   fuzz_rig_state tests/fuzz/corpus_rig_state -max_total_time=20
 *
 * JUNO_FUZZ_SEEDS=DIR writes this build's seed corpus into DIR when the
 * first input runs: the valid state (mode 0), a truncated one, and for the
 * header and each part of the model's state (parameters, derived values,
 * inputs, integrator state) one input of mode 1 and one of mode 2 aimed at
 * it, and one that multiplies the Wong-Reece law's Simpson interval count
 * (a hang before the FMU checked it).  The committed corpora were written so:
 *
 *   touch empty && JUNO_FUZZ_SEEDS=tests/fuzz/corpus_rig_state build-asan/fuzz_rig_state empty
 */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2.h"
#include "juno_guid.h"
#include JUNO_MODEL_HEADER   /* ModelState: where each part of a serialized state lies */

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static fmi2Component inst;
static fmi2FMUstate good;          /* the valid state, restored before every input */
static char *valid;                /* its serialized bytes */
static size_t valid_size;
static int errors_logged;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)name;
    (void)category;
    (void)message;
    if (status >= fmi2Error) errors_logged++;
    if (getenv("JUNO_FUZZ_VERBOSE")) {
        va_list ap;
        va_start(ap, message);
        vfprintf(stderr, message, ap);
        va_end(ap);
        fputc('\n', stderr);
    }
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
/* The layout fmi2_cs.c serializes (its Snapshot), then a checksum; setup()
 * checks that the sizes agree. */
typedef struct {
    uint64_t magic;
    uint32_t version, fmi_state;
    ModelState model;
} SnapshotLayout;

#if defined(JUNO_FUZZ_RIG)
/* WheelRig (modelDescription/wheel_rig_variables.h): rig.drawbarPull .. rig.hubHeight */
static const unsigned outputs[] = {800, 801, 802, 803, 804, 805, 806, 807, 808, 809, 810};
#define STATE_STEP 0.02
#else
/* JunoRover (modelDescription/variables.h): the rover's pose and speeds */
static const unsigned outputs[] = {300, 301, 302, 303, 304, 305, 306, 307, 308, 309, 310};
#define STATE_STEP 0.01
#endif

#define FUZZ_STEP 1e-3   /* s, the communication step after a state is set */

/* Brings the instance to a state worth fuzzing: mid-run, every part of the
 * state in use. */
static int start_model(void)
{
#if defined(JUNO_FUZZ_RIG)
    /* the Wong-Reece law (the rover's target fuzzes the volumetric one), rolling at 30 % slip
     * with a slip angle: the soil memory, sinkage and lateral force in use */
    const unsigned vr_model = 183, vr_in[3] = {710, 711, 713};   /* contact.model; rig.slip, rig.vx, rig.slipAngle */
    const fmi2Integer wong_reece = 1;
    const fmi2Real in[3] = {0.3, 0.1, 0.05};
    return fmi2SetupExperiment(inst, fmi2False, 0, 0.0, fmi2False, 0) == fmi2OK &&
           fmi2EnterInitializationMode(inst) == fmi2OK && fmi2SetInteger(inst, &vr_model, 1, &wong_reece) == fmi2OK &&
           fmi2SetReal(inst, vr_in, 3, in) == fmi2OK && fmi2ExitInitializationMode(inst) == fmi2OK;
#else
    const unsigned vr_mode = 150, vr_in[3] = {200, 203, 204};
    const fmi2Integer mode = 1;   /* PID drive: integral state in use */
    const fmi2Real in[3] = {150.0, 1.0, 1.2};
    return fmi2SetupExperiment(inst, fmi2False, 0, 0.0, fmi2False, 0) == fmi2OK &&
           fmi2EnterInitializationMode(inst) == fmi2OK && fmi2SetInteger(inst, &vr_mode, 1, &mode) == fmi2OK &&
           fmi2SetReal(inst, vr_in, 3, in) == fmi2OK && fmi2ExitInitializationMode(inst) == fmi2OK;
#endif
}

/* The checksum of the serialized layout (fmu_src/fmi2_cs.c): 64-bit FNV-1a
 * of everything before the last 8 bytes, stored in them. */
static void fix_checksum(char *buf, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i + 8 < n; ++i) {
        h ^= (unsigned char)buf[i];
        h *= 1099511628211ull;
    }
    memcpy(buf + n - 8, &h, 8);
}

static void write_seed(const char *dir, const char *name, int mode, size_t at, const void *bytes, size_t n)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    if (!f) {
        fprintf(stderr, "fuzz: cannot write the seed %s: %s\n", path, strerror(errno));
        exit(1);
    }
    fputc(mode, f);
    if (mode != 0) {   /* the offset, little-endian */
        fputc((int)(at & 0xff), f);
        fputc((int)(at >> 8 & 0xff), f);
    }
    fwrite(bytes, 1, n, f);
    if (fclose(f) != 0) {
        fprintf(stderr, "fuzz: cannot write the seed %s: %s\n", path, strerror(errno));
        exit(1);
    }
}

/* This build's seed corpus (see the head of this file) into dir. */
static void write_seeds(const char *dir)
{
    static const struct {
        const char *name;
        size_t at;
    } parts[] = {
        {"header", 0},
        {"params", offsetof(SnapshotLayout, model) + offsetof(ModelState, p)},
        {"derived", offsetof(SnapshotLayout, model) + offsetof(ModelState, d)},
        {"inputs", offsetof(SnapshotLayout, model) + offsetof(ModelState, in)},
        {"state", offsetof(SnapshotLayout, model) + offsetof(ModelState, s)},
    };
    /* the Wong-Reece law's Simpson interval count, 2^28 times larger: refused, or every step of the
     * law would take hours */
    static const unsigned char intervals_flip[] = {0x00, 0x00, 0x00, 0x10};
    const size_t intervals_at =
        offsetof(SnapshotLayout, model) + offsetof(ModelState, d) + offsetof(Derived, wong_reece) +
        offsetof(WongReeceModel, intervals);
    /* mode 1: flip a sign bit, a low bit, a whole word; mode 2: each special value once */
    static const unsigned char flips[] = {0x20, 0x01, 0xff, 0xff, 0xff, 0xff, 0x00, 0x80};
    static const unsigned char specials[] = {0, 2, 4, 6, 8, 10, 12, 14, 16};
    char name[64];
    write_seed(dir, "valid_state", 0, 0, valid, valid_size);
    write_seed(dir, "raw_short", 0, 0, valid, 8);
    for (size_t i = 0; i < sizeof parts / sizeof parts[0]; ++i) {
        snprintf(name, sizeof name, "xor_%s", parts[i].name);
        write_seed(dir, name, 1, parts[i].at, flips, sizeof flips);
        if (parts[i].at == 0) continue;   /* the header holds no doubles */
        snprintf(name, sizeof name, "special_%s", parts[i].name);
        write_seed(dir, name, 2, parts[i].at, specials, sizeof specials);
    }
    write_seed(dir, "xor_wong_reece_intervals", 1, intervals_at, intervals_flip, sizeof intervals_flip);
}

static void setup(void)
{
    inst = fmi2Instantiate("fuzz", fmi2CoSimulation, JUNO_GUID, NULL, &callbacks, fmi2False, fmi2False);
    if (!inst || !start_model()) abort();
    for (int k = 0; k < 50; ++k)
        if (fmi2DoStep(inst, k * STATE_STEP, STATE_STEP, fmi2True) != fmi2OK) abort();
    if (fmi2GetFMUstate(inst, &good) != fmi2OK || fmi2SerializedFMUstateSize(inst, good, &valid_size) != fmi2OK)
        abort();
    if (valid_size != sizeof(SnapshotLayout) + sizeof(uint64_t)) {
        fprintf(stderr, "fuzz: the serialized state has %zu bytes, SnapshotLayout says %zu: update it\n", valid_size,
                sizeof(SnapshotLayout) + sizeof(uint64_t));
        abort();
    }
    valid = (char *)malloc(valid_size);
    if (!valid || fmi2SerializeFMUstate(inst, good, valid, valid_size) != fmi2OK) abort();
    const char *seeds = getenv("JUNO_FUZZ_SEEDS");
    if (seeds) write_seeds(seeds);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!inst) setup();
    if (size < 1) return 0;
    if (fmi2SetFMUstate(inst, good) != fmi2OK) abort();
    const int mode = data[0] % 3;
    char *buf;
    size_t n;
    if (mode == 0) {
        n = size - 1;
        buf = (char *)malloc(n ? n : 1);
        if (!buf) return 0;
        if (n) memcpy(buf, data + 1, n);
    } else {
        if (size < 3) return 0;
        n = valid_size;
        buf = (char *)malloc(n);
        if (!buf) return 0;
        memcpy(buf, valid, n);
        size_t at = ((size_t)data[1] | (size_t)data[2] << 8) % (n - 8);
        if (mode == 1) {
            for (size_t i = 3; i < size && at < n - 8; ++i, ++at) buf[at] ^= (char)data[i];
        } else {
            static const double special[] = {NAN, INFINITY, -INFINITY, 0.0, -1.0, 1e300, -1e300, 1e-300, 1e9};
            at &= ~(size_t)7;
            for (size_t i = 3; i < size && at + 8 <= n - 8; ++i, at += 8) {
                if (data[i] % 2) continue;   /* keep this double */
                double v = special[(data[i] / 2) % (sizeof special / sizeof special[0])];
                memcpy(buf + at, &v, 8);
            }
        }
        fix_checksum(buf, n);
    }
    fmi2FMUstate st = NULL;
    int before = errors_logged;
    fmi2Status s = fmi2DeSerializeFMUstate(inst, buf, n, &st);
    if (s != fmi2OK) {
        if (st != NULL || errors_logged == before) abort();   /* refused: nothing allocated, explained */
    } else {
        if (!st) abort();
        before = errors_logged;
        s = fmi2SetFMUstate(inst, st);
        if (s != fmi2OK && errors_logged == before) abort();
        if (s == fmi2OK) {
            fmi2Real t = 0, y[sizeof outputs / sizeof outputs[0]];
            fmi2GetReal(inst, outputs, sizeof outputs / sizeof outputs[0], y);
            if (fmi2GetRealStatus(inst, fmi2LastSuccessfulTime, &t) == fmi2OK) {
                /* One communication step of FUZZ_STEP: an internal step is never shorter than
                 * 1e-6 s (the least solver.step, and the floor of the rover's automatic step),
                 * so it takes at most 1e3 internal steps, each tried a few times at most by the
                 * automatic step, whatever a crafted state's parameters: every input costs
                 * little. */
                const fmi2Real h = FUZZ_STEP;
                before = errors_logged;
                s = fmi2DoStep(inst, t, h, fmi2False);
                if (s != fmi2OK && errors_logged == before) abort();
                fmi2GetReal(inst, outputs, sizeof outputs / sizeof outputs[0], y);
            }
        }
        fmi2FreeFMUstate(inst, &st);
    }
    free(buf);
    return 0;
}
