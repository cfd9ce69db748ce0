/*
 * Writes an FMU's modelDescription.xml, or its documentation/index.html, from
 * the FMU's variable table, so the FMU's documentation cannot disagree with it.
 * Built once per FMU (CMakeLists.txt): the generated juno_guid.h names the
 * model (JUNO_MODEL_NAME) and its table (JUNO_VARIABLE_TABLE: variables.h for
 * JunoRover, wheel_rig_variables.h for WheelRig); what the documents say
 * about the model beyond its variables is in `models` below.
 * usage: generate OUT.xml GUID SOURCE.c...   (sources listed for the
 *        source-code FMU's <SourceFiles>)
 *        generate --html OUT.html
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "juno_guid.h"

#define PARAM  'P'
#define CALC   'C'
#define INPUT  'I'
#define OUTPUT 'O'
#include JUNO_VARIABLE_TABLE

#ifndef JUNO_VERSION
#error "JUNO_VERSION (the project's version) must be defined by the build"
#endif

/* What the documents say about a model beyond its variables. */
typedef struct {
    const char *name;              /* model name and identifier */
    const char *description;       /* modelDescription's description attribute */
    const char *html_about;        /* index.html: what the model is (HTML) */
    const char *html_experiment;   /* index.html: the default experiment (HTML) */
    const char *html_use;          /* index.html: how to run it (HTML) */
    const char *log_events;        /* what the logEvents category reports */
    double stop_time, step_size;   /* the default experiment, s */
} ModelInfo;

static const ModelInfo models[] = {
    {"JunoRover",
     "CSA Juno rover with the volumetric wheel/soil contact model of Petersen and McPhee (2013)",
     "<p>The CSA Juno rover (four wheels, skid steered, a rocker suspension with a transverse "
     "differential, a drawbar hitch) on soft soil, with the volumetric wheel/soil contact model of "
     "Petersen and McPhee, &ldquo;Experimental validation of a volumetric planetary rover wheel/soil "
     "interaction model&rdquo;, ASME IDETC/CIE 2013, DETC2013-13486. The normal force of each wheel is "
     "the soil's foundation stiffness times the hypervolume the rim cuts into the soil; traction follows "
     "the slip. The rover starts in static equilibrium on flat ground, or on a 3-D terrain grid "
     "(<code>terrain.file</code>, ESRI ASCII).</p>\n"
     "<p><img src=\"wheel-and-drawbar.png\" alt=\"A wheel in soil under the volumetric law, and the "
     "drawbar pull against slip\" style=\"max-width:100%\"></p>\n",
     "<p>A 30 s drawbar pull test on flat ground at the start values: 0 to 30 s, communication step "
     "0.01 s. <code>extra/JunoRover_ref.csv</code> holds its reference result.</p>\n",
     "<p>FMI 2.0 Co-Simulation: variable communication step size, get, set and "
     "serialize the FMU state, many instances per process. Inputs act from the next "
     "<code>fmi2DoStep</code>: no output depends directly on an input. Choose the drive with "
     "<code>drive.mode</code>: 0 torque inputs, 1 wheel-spin references (PID), 2 DC motor throttles. "
     "Parameters outside their range are refused with a message naming them.</p>\n",
     "Initialisation summary (equilibrium, contact fit)", 30.0, 0.01},
    {"WheelRig",
     "Single-wheel test rig: one rigid wheel on soft soil at a set slip, with the wheel/soil contact laws of "
     "JunoRover (the volumetric model of Petersen and McPhee (2013), or Wong-Reece)",
     "<p>A single-wheel test rig: one rigid wheel on flat soft soil under a carriage that moves it forward "
     "at <code>rig.vx</code>. The hub is free vertically under the load <code>rig.load</code>; the wheel's "
     "spin is imposed, from a slip (<code>rig.driveMode</code> 0) or a spin rate (1); "
     "<code>rig.slipAngle</code> turns the wheel against the carriage's direction. The soil's force on the "
     "wheel is JunoRover's: the volumetric wheel/soil contact model of Petersen and McPhee, "
     "&ldquo;Experimental validation of a volumetric planetary rover wheel/soil interaction model&rdquo;, "
     "ASME IDETC/CIE 2013, DETC2013-13486 (<code>contact.model</code> 0) or the Wong-Reece/Ishigami law "
     "(1), with the same extensions. The wheel starts at rest in static equilibrium, pressed into virgin "
     "soil; the outputs are steady after it has rolled about one contact length.</p>\n",
     "<p>A 10 s run at the start values (slip 0.2 at 5 cm/s): 0 to 10 s, communication step 0.01 s.</p>\n",
     "<p>FMI 2.0 Co-Simulation: variable communication step size, get, set and "
     "serialize the FMU state, many instances per process. Inputs act from the next "
     "<code>fmi2DoStep</code>: no output depends directly on an input. The drawbar pull, vertical force, "
     "lateral force and torque are the soil's force and moment on the wheel. "
     "Parameters outside their range are refused with a message naming them.</p>\n",
     "Initialisation summary (contact law, static sinkage)", 10.0, 0.01},
};

/* The entry of the model this generator is built for. */
static const ModelInfo *model_info(void)
{
    for (size_t i = 0; i < sizeof models / sizeof models[0]; ++i)
        if (strcmp(models[i].name, JUNO_MODEL_NAME) == 0) return &models[i];
    return NULL;
}

static void put_escaped(FILE *f, const char *s)
{
    for (; *s; ++s) {
        switch (*s) {
        case '&': fputs("&amp;", f); break;
        case '<': fputs("&lt;", f); break;
        case '>': fputs("&gt;", f); break;
        case '"': fputs("&quot;", f); break;
        default: fputc(*s, f);
        }
    }
}

static const char *causality(int kind)
{
    switch (kind) {
    case PARAM: return "parameter";
    case CALC: return "calculatedParameter";
    case INPUT: return "input";
    default: return "output";
    }
}

static const char *variability(int kind)
{
    return (kind == PARAM || kind == CALC) ? "fixed" : "continuous";
}

static void open_var(FILE *f, const char *name, unsigned vr, int kind, const char *desc)
{
    fprintf(f, "    <ScalarVariable name=\"%s\" valueReference=\"%u\" causality=\"%s\" variability=\"%s\"",
            name, vr, causality(kind), variability(kind));
    if (kind == CALC || kind == OUTPUT) fputs(" initial=\"calculated\"", f);
    fputs(" description=\"", f);
    put_escaped(f, desc);
    fputs("\">\n", f);
}

static void real_var(FILE *f, const char *name, unsigned vr, int kind, const char *unit,
                     double start, double lo, double hi, const char *desc)
{
    open_var(f, name, vr, kind, desc);
    fprintf(f, "      <Real unit=\"");
    put_escaped(f, unit);
    fputc('"', f);
    if (kind == PARAM || kind == INPUT) {
        fprintf(f, " start=\"%.17g\"", start);
        if (isfinite(lo)) fprintf(f, " min=\"%.17g\"", lo);
        if (isfinite(hi)) fprintf(f, " max=\"%.17g\"", hi);
    }
    fputs("/>\n    </ScalarVariable>\n", f);
}

static void int_var(FILE *f, const char *name, unsigned vr, int kind, int start, int lo, int hi,
                    const char *desc)
{
    open_var(f, name, vr, kind, desc);
    fprintf(f, "      <Integer start=\"%d\" min=\"%d\" max=\"%d\"/>\n    </ScalarVariable>\n",
            start, lo, hi);
}

static void str_var(FILE *f, const char *name, unsigned vr, int kind, const char *start,
                    const char *desc)
{
    open_var(f, name, vr, kind, desc);
    fputs("      <String start=\"", f);
    put_escaped(f, start);
    fputs("\"/>\n    </ScalarVariable>\n", f);
}

/* SI decomposition of every unit the table uses. */
static const struct { const char *name, *base; } units[] = {
    {"1", ""}, {"m", "m=\"1\""}, {"m/s", "m=\"1\" s=\"-1\""}, {"m/s2", "m=\"1\" s=\"-2\""},
    {"m3", "m=\"3\""}, {"rad", "rad=\"1\""}, {"rad/s", "rad=\"1\" s=\"-1\""},
    {"s", "s=\"1\""}, {"kg", "kg=\"1\""}, {"kg.m2", "kg=\"1\" m=\"2\""},
    {"N", "kg=\"1\" m=\"1\" s=\"-2\""}, {"N.m", "kg=\"1\" m=\"2\" s=\"-2\""},
    {"Pa", "kg=\"1\" m=\"-1\" s=\"-2\""},
    {"N.m.s/rad", "kg=\"1\" m=\"2\" s=\"-1\" rad=\"-1\""},
    {"N.m/rad", "kg=\"1\" m=\"2\" s=\"-2\" rad=\"-1\""},
    {"N.m.s2/rad", "kg=\"1\" m=\"2\" rad=\"-1\""},
    {"V", "kg=\"1\" m=\"2\" s=\"-3\" A=\"-1\""}, {"Ohm", "kg=\"1\" m=\"2\" s=\"-3\" A=\"-2\""},
    {"N.m/A", "kg=\"1\" m=\"2\" s=\"-2\" A=\"-1\""},
    /* the exponent depends on eta, so no fixed SI decomposition exists */
    {"N/m^(2+eta)", NULL},
    /* Bekker moduli (wongReece.kc, kphi): the exponent depends on n */
    {"N/m^(n+1)", NULL}, {"N/m^(n+2)", NULL},
};

static void html_cell_number(FILE *f, double v)
{
    if (isfinite(v)) fprintf(f, "<td>%.6g</td>", v);
    else fputs("<td></td>", f);
}

static void html_row(FILE *f, const char *name, int kind, const char *type, const char *unit,
                     const char *start, double lo, double hi, const char *desc)
{
    fputs("<tr><td><code>", f);
    put_escaped(f, name);
    fprintf(f, "</code></td><td>%s</td><td>%s</td><td>", causality(kind), type);
    put_escaped(f, unit);
    fputs("</td><td>", f);
    put_escaped(f, start);
    fputs("</td>", f);
    html_cell_number(f, lo);
    html_cell_number(f, hi);
    fputs("<td>", f);
    put_escaped(f, desc);
    fputs("</td></tr>\n", f);
}

static void html_real(FILE *f, const char *name, int kind, const char *unit, double start, double lo,
                      double hi, const char *desc)
{
    char text[32] = "";
    if (kind == PARAM || kind == INPUT) snprintf(text, sizeof text, "%.6g", start);
    html_row(f, name, kind, "Real", unit, text, (kind == PARAM || kind == INPUT) ? lo : NAN,
             (kind == PARAM || kind == INPUT) ? hi : NAN, desc);
}

static void html_int(FILE *f, const char *name, int kind, int start, int lo, int hi, const char *desc)
{
    char text[32];
    snprintf(text, sizeof text, "%d", start);
    html_row(f, name, kind, "Integer", "", text, lo, hi, desc);
}

/* documentation/index.html: what the model is, how to run it, and every variable. */
static int write_html(const ModelInfo *info, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        perror(path);
        return 1;
    }
    fprintf(f, "<!DOCTYPE html>\n<html lang=\"en\">\n<head><meta charset=\"utf-8\"><title>%s</title>\n"
            "<style>body{font-family:sans-serif;max-width:70em;margin:2em auto}table{border-collapse:collapse}"
            "td,th{border:1px solid #ccc;padding:2px 6px;font-size:90%%;vertical-align:top}</style></head>\n<body>\n"
            "<h1>%s " JUNO_VERSION "</h1>\n", info->name, info->name);
    fputs(info->html_about, f);
    fputs("<h2>Default experiment</h2>\n", f);
    fputs(info->html_experiment, f);
    fputs("<h2>Use</h2>\n", f);
    fputs(info->html_use, f);
    fputs("<h2>Variables</h2>\n<table>\n<tr><th>name</th><th>causality</th><th>type</th><th>unit</th>"
          "<th>start</th><th>min</th><th>max</th><th>description</th></tr>\n", f);
#define REAL(vr, name, kind, unit, start, lo, hi, field, desc) html_real(f, name, kind, unit, start, lo, hi, desc);
#define INT(vr, name, kind, start, lo, hi, field, desc) html_int(f, name, kind, start, lo, hi, desc);
#define STR(vr, name, kind, start, field, desc) html_row(f, name, kind, "String", "", start, NAN, NAN, desc);
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    fputs("</table>\n<h2>Licence</h2>\n<p>BSD-2-Clause, copyright 2026, the JunoRover authors: "
          "<a href=\"licenses/LICENSE.txt\">licenses/LICENSE.txt</a>.</p>\n</body>\n</html>\n", f);
    if (fclose(f) != 0) {
        perror(path);
        return 1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    const ModelInfo *info = model_info();
    if (!info) {
        fprintf(stderr, "%s: no description of the model '%s' (modelDescription/generate.c, models)\n", argv[0],
                JUNO_MODEL_NAME);
        return 2;
    }
    if (argc == 3 && strcmp(argv[1], "--html") == 0) return write_html(info, argv[2]);
    if (argc < 3) {
        fprintf(stderr, "usage: %s OUT.xml GUID [SOURCE.c...] | --html OUT.html\n", argv[0]);
        return 2;
    }
    FILE *f = fopen(argv[1], "w");
    if (!f) {
        perror(argv[1]);
        return 1;
    }
    fprintf(f,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"%s\" guid=\"%s\"\n"
        "  description=\"", info->name, argv[2]);
    put_escaped(f, info->description);
    fprintf(f, "\"\n"
        "  author=\"the JunoRover authors\" version=\"" JUNO_VERSION "\" copyright=\"Copyright 2026, the JunoRover authors\"\n"
        "  license=\"BSD-2-Clause (documentation/licenses/LICENSE.txt)\"\n"
        "  generationTool=\"juno modelDescription/generate.c\" variableNamingConvention=\"structured\"\n"
        "  numberOfEventIndicators=\"0\">\n"
        "  <CoSimulation modelIdentifier=\"%s\" canHandleVariableCommunicationStepSize=\"true\"\n"
        "    canGetAndSetFMUstate=\"true\" canSerializeFMUstate=\"true\" canNotUseMemoryManagementFunctions=\"true\"\n"
        "    canInterpolateInputs=\"false\" maxOutputDerivativeOrder=\"0\" canRunAsynchronuously=\"false\"\n"
        "    canBeInstantiatedOnlyOncePerProcess=\"false\" providesDirectionalDerivative=\"false\">\n",
        info->name);
    if (argc > 3) {
        fputs("    <SourceFiles>\n", f);
        for (int i = 3; i < argc; ++i) fprintf(f, "      <File name=\"%s\"/>\n", argv[i]);
        fputs("    </SourceFiles>\n", f);
    }
    fputs("  </CoSimulation>\n  <UnitDefinitions>\n", f);
    for (size_t i = 0; i < sizeof units / sizeof units[0]; ++i) {
        fputs("    <Unit name=\"", f);
        put_escaped(f, units[i].name);
        if (units[i].base == NULL) fputs("\"/>\n", f);
        else fprintf(f, "\">\n      <BaseUnit %s/>\n    </Unit>\n", units[i].base);
    }
    fputs("  </UnitDefinitions>\n"
          "  <LogCategories>\n"
          "    <Category name=\"logStatusError\" description=\"Errors: bad parameters, inputs, files, diverging state\"/>\n"
          "    <Category name=\"logStatusWarning\" description=\"Warnings\"/>\n"
          "    <Category name=\"logEvents\" description=\"", f);
    put_escaped(f, info->log_events);
    fprintf(f, "\"/>\n"
            "    <Category name=\"logCalls\" description=\"Every FMI call\"/>\n"
            "  </LogCategories>\n"
            "  <DefaultExperiment startTime=\"0\" stopTime=\"%g\" stepSize=\"%g\"/>\n"
            "  <ModelVariables>\n", info->stop_time, info->step_size);
#define REAL(vr, name, kind, unit, start, lo, hi, field, desc) real_var(f, name, vr, kind, unit, start, lo, hi, desc);
#define INT(vr, name, kind, start, lo, hi, field, desc) int_var(f, name, vr, kind, start, lo, hi, desc);
#define STR(vr, name, kind, start, field, desc) str_var(f, name, vr, kind, start, desc);
    (void)str_var;   /* unused when the table has no String variable */
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    fputs("  </ModelVariables>\n  <ModelStructure>\n    <Outputs>\n", f);
    int index = 0;
    /* dependencies="": no output depends directly on an input.  Outputs are the values the
     * model stored at the end of the last step (model_get_real reads a field, computes
     * nothing), so setting an input changes no output until the next fmi2DoStep.  Without the
     * attribute an importer must assume every output depends on every input and sees
     * algebraic loops that do not exist. */
#define REAL(vr, name, kind, unit, start, lo, hi, field, desc) ++index; if (kind == OUTPUT) fprintf(f, "      <Unknown index=\"%d\" dependencies=\"\"/>\n", index);
#define INT(vr, name, kind, start, lo, hi, field, desc) ++index;
#define STR(vr, name, kind, start, field, desc) ++index;
    JUNO_VARIABLES
    fputs("    </Outputs>\n    <InitialUnknowns>\n", f);
    index = 0;
#undef REAL
#define REAL(vr, name, kind, unit, start, lo, hi, field, desc) ++index; if (kind == OUTPUT || kind == CALC) fprintf(f, "      <Unknown index=\"%d\"/>\n", index);
    JUNO_VARIABLES
#undef REAL
#undef INT
#undef STR
    fputs("    </InitialUnknowns>\n  </ModelStructure>\n</fmiModelDescription>\n", f);
    if (fclose(f) != 0) {
        perror(argv[1]);
        return 1;
    }
    return 0;
}
