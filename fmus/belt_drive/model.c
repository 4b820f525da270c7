/* BeltDrive model equations: see readme.md for the derivation, units and parameter sources. */
#include <math.h>
#include <stdbool.h>

#include "model.h"

#define GRAVITY_MPS2 9.80665
#define MAX_INTERNAL_STEP_S 1e-3

typedef enum { Positive, NonNegative, UnitInterval, StepSize } Rule;

typedef struct {
    const char *name;
    double *field;
    Rule rule;
    bool isParameter;
} Float64Variable;

static bool float64Variable(ModelInstance *comp, ValueReference vr, Float64Variable *out) {
    ModelData *d = &comp->data;
    switch (vr) {
#define PARAMETER(vr_name, field_name, rule_kind)                                            \
    case vr_name:                                                                            \
        *out = (Float64Variable){#field_name, &d->field_name, rule_kind, true};             \
        return true;
        PARAMETER(vr_torque_constant_NmpA, torque_constant_NmpA, Positive)
        PARAMETER(vr_current_limit_A, current_limit_A, Positive)
        PARAMETER(vr_speed_gain_Aspm, speed_gain_Aspm, NonNegative)
        PARAMETER(vr_integral_gain_Apm, integral_gain_Apm, NonNegative)
        PARAMETER(vr_antiwindup_time_s, antiwindup_time_s, Positive)
        PARAMETER(vr_gear_ratio, gear_ratio, Positive)
        PARAMETER(vr_drum_radius_m, drum_radius_m, Positive)
        PARAMETER(vr_motor_inertia_kgm2, motor_inertia_kgm2, Positive)
        PARAMETER(vr_drum_inertia_kgm2, drum_inertia_kgm2, Positive)
        PARAMETER(vr_belt_mass_kg, belt_mass_kg, Positive)
        PARAMETER(vr_viscous_friction_Nspm, viscous_friction_Nspm, NonNegative)
        PARAMETER(vr_coulomb_friction_N, coulomb_friction_N, NonNegative)
        PARAMETER(vr_load_friction_coefficient, load_friction_coefficient, NonNegative)
        PARAMETER(vr_coulomb_smoothing_speed_mps, coulomb_smoothing_speed_mps, Positive)
        PARAMETER(vr_perturbation_std_N, perturbation_std_N, NonNegative)
        PARAMETER(vr_perturbation_correlation_time_s, perturbation_correlation_time_s, Positive)
        PARAMETER(vr_setpoint_ramp_limit_mps2, setpoint_ramp_limit_mps2, NonNegative)
        PARAMETER(vr_internal_step_s, internal_step_s, StepSize)
        PARAMETER(vr_setpoint_weight, setpoint_weight, UnitInterval)
        PARAMETER(vr_standstill_speed_mps, standstill_speed_mps, Positive)
#undef PARAMETER
    case vr_speed_setpoint_mps:
        *out = (Float64Variable){"speed_setpoint_mps", &d->speed_setpoint_mps, NonNegative, false};
        return true;
    case vr_load_mass_kg:
        *out = (Float64Variable){"load_mass_kg", &d->load_mass_kg, NonNegative, false};
        return true;
    default:
        return false;
    }
}

static Status checkValue(const ModelInstance *comp, const Float64Variable *v, double value) {
    const char *requirement = NULL;
    switch (v->rule) {
    case Positive:
        if (!(isfinite(value) && value > 0.0)) requirement = "a finite value > 0";
        break;
    case NonNegative:
        if (!(isfinite(value) && value >= 0.0)) requirement = "a finite value >= 0";
        break;
    case UnitInterval:
        if (!(isfinite(value) && value >= 0.0 && value <= 1.0)) requirement = "a value in [0, 1]";
        break;
    case StepSize:
        if (!(isfinite(value) && value > 0.0 && value <= MAX_INTERNAL_STEP_S)) {
            requirement = "a value in (0, 0.001]";
        }
        break;
    }
    if (requirement) {
        logError(comp, "%s = %g is invalid: %s requires %s.", v->name, value, v->name, requirement);
        return Error;
    }
    return OK;
}

void setStartValues(ModelInstance *comp) {
    ModelData *d = &comp->data;
    d->torque_constant_NmpA = 0.7;
    d->current_limit_A = 9.0;
    d->speed_gain_Aspm = 24.0;
    d->integral_gain_Apm = 168.0;
    d->antiwindup_time_s = 0.05;
    d->gear_ratio = 40.0;
    d->drum_radius_m = 0.1;
    d->motor_inertia_kgm2 = 2.0e-4;
    d->drum_inertia_kgm2 = 0.3;
    d->belt_mass_kg = 30.0;
    d->viscous_friction_Nspm = 20.0;
    d->coulomb_friction_N = 50.0;
    d->load_friction_coefficient = 0.33;
    d->coulomb_smoothing_speed_mps = 0.01;
    d->perturbation_std_N = 0.0;
    d->perturbation_correlation_time_s = 0.5;
    d->perturbation_seed = 1;
    d->setpoint_ramp_limit_mps2 = 0.5;
    d->internal_step_s = 1e-3;
    d->setpoint_weight = 0.7;
    d->standstill_speed_mps = 0.005;
    d->speed_setpoint_mps = 0.0;
    d->load_mass_kg = 0.0;
}

Status validateParameters(ModelInstance *comp) {
    static const ValueReference all[] = {
        vr_torque_constant_NmpA, vr_current_limit_A, vr_speed_gain_Aspm, vr_integral_gain_Apm,
        vr_antiwindup_time_s, vr_gear_ratio, vr_drum_radius_m, vr_motor_inertia_kgm2,
        vr_drum_inertia_kgm2, vr_belt_mass_kg, vr_viscous_friction_Nspm, vr_coulomb_friction_N,
        vr_load_friction_coefficient, vr_coulomb_smoothing_speed_mps, vr_perturbation_std_N,
        vr_perturbation_correlation_time_s, vr_setpoint_ramp_limit_mps2, vr_internal_step_s,
        vr_setpoint_weight, vr_standstill_speed_mps, vr_speed_setpoint_mps, vr_load_mass_kg};
    for (size_t i = 0; i < sizeof(all) / sizeof(all[0]); i++) {
        Float64Variable v;
        float64Variable(comp, all[i], &v);
        if (checkValue(comp, &v, *v.field) > Warning) return Error;
    }
    return OK;
}

static uint64_t splitmix64(uint64_t *state) {
    uint64_t z = (*state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t xoshiro256ss(uint64_t s[4]) {
    const uint64_t result = rotl(s[1] * 5, 7) * 9;
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Standard normal sample by Box-Muller (cosine branch) from two uniforms in (0, 1]. */
static double standardNormal(uint64_t s[4]) {
    const double u1 = (double)((xoshiro256ss(s) >> 11) + 1) * 0x1.0p-53;
    const double u2 = (double)((xoshiro256ss(s) >> 11) + 1) * 0x1.0p-53;
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

Status initializeModel(ModelInstance *comp) {
    ModelData *d = &comp->data;
    const double h = d->internal_step_s;
    uint64_t seed = (uint64_t)(uint32_t)d->perturbation_seed;
    for (int i = 0; i < 4; i++) d->rng[i] = splitmix64(&seed);
    d->ou_decay = exp(-h / d->perturbation_correlation_time_s);
    d->ou_diffusion_N =
        d->perturbation_std_N * sqrt(-expm1(-2.0 * h / d->perturbation_correlation_time_s));
    d->perturbation_N =
        d->perturbation_std_N > 0.0 ? d->perturbation_std_N * standardNormal(d->rng) : 0.0;
    d->reference_mps = 0.0;
    d->reference_hold_mps = 0.0;
    d->brake_closed = true;
    d->brake_hold = true;
    d->interval_start_position_m = 0.0;
    comp->x[0] = 0.0;
    comp->x[1] = 0.0;
    comp->x[2] = 0.0;
    return OK;
}

double internalStepSize(const ModelInstance *comp) { return comp->data.internal_step_s; }

/* The drive is enabled while the belt runs and, with the brake closed, while a speed is commanded;
 * a disabled drive (stopped, brake closed, setpoint 0) carries no current. */
static bool driveEnabled(const ModelData *d) {
    return !d->brake_hold || d->speed_setpoint_mps > 0.0;
}

/* Motor current (A) of the PI with setpoint weight b; *command is the unlimited command u. */
static double motorCurrent(const ModelData *d, const double x[NX], double *command) {
    if (!driveEnabled(d)) {
        *command = 0.0;
        return 0.0;
    }
    const double weighted_mps = d->setpoint_weight * d->reference_hold_mps;
    const double u = d->speed_gain_Aspm * (weighted_mps - x[0]) + x[2];
    *command = u;
    return fmin(fmax(u, -d->current_limit_A), d->current_limit_A);
}

/* Drive force at the belt per ampere of motor current (N/A). */
static double forcePerAmpere(const ModelData *d) {
    return d->torque_constant_NmpA * d->gear_ratio / d->drum_radius_m;
}

/* Whether the drive closes the brake on a belt that ran over this interval and ends it at
 * state x: it would turn backwards, or a stop is commanded and its speed is within the
 * standstill threshold. */
static bool closesBrake(const ModelData *d, const double x[NX]) {
    return !d->brake_hold &&
           (x[0] <= 0.0 || (d->speed_setpoint_mps == 0.0 && x[0] <= d->standstill_speed_mps));
}

/* The closing brake stops the belt where it is: speed 0, position not behind the interval's
 * start. */
static void holdBelt(const ModelData *d, double x[NX]) {
    x[0] = 0.0;
    x[1] = fmax(x[1], d->interval_start_position_m);
}

void prepareInterval(ModelInstance *comp, double h) {
    ModelData *d = &comp->data;
    if (d->setpoint_ramp_limit_mps2 > 0.0) {
        const double maxChange = d->setpoint_ramp_limit_mps2 * h;
        const double change = fmin(fmax(d->speed_setpoint_mps - d->reference_mps, -maxChange),
                                   maxChange);
        d->reference_hold_mps = d->reference_mps + change;
    } else {
        d->reference_hold_mps = d->speed_setpoint_mps;
    }
    d->brake_hold = d->brake_closed;
    if (d->brake_closed && d->speed_setpoint_mps > 0.0) {
        /* The brake opens once the drive's force, with the perturbation, pushes forward. */
        double command_A;
        const double force_N = forcePerAmpere(d) * motorCurrent(d, comp->x, &command_A);
        d->brake_hold = !(force_N + d->perturbation_N > 0.0);
    }
    d->interval_start_position_m = comp->x[1];
}

void commitInterval(ModelInstance *comp, double h) {
    (void)h;
    ModelData *d = &comp->data;
    d->reference_mps = d->reference_hold_mps;
    d->brake_closed = d->brake_hold;
    if (closesBrake(d, comp->x)) {
        d->brake_closed = true;
        holdBelt(d, comp->x);
        if (d->speed_setpoint_mps == 0.0) {
            comp->x[2] = 0.0; /* stopped: drive disabled, integrator and ramp reset */
            d->reference_mps = 0.0;
        }
    }
    if (d->perturbation_std_N > 0.0) {
        d->perturbation_N = d->ou_decay * d->perturbation_N +
                            d->ou_diffusion_N * standardNormal(d->rng);
    }
}

void getDerivatives(const ModelInstance *comp, const double x[NX], double dx[NX]) {
    const ModelData *d = &comp->data;
    double command_A;
    const double current_A = motorCurrent(d, x, &command_A);
    dx[2] = driveEnabled(d) ? d->integral_gain_Apm * (d->reference_hold_mps - x[0]) +
                                  (current_A - command_A) / d->antiwindup_time_s
                            : 0.0;
    if (d->brake_hold) {
        dx[0] = 0.0;
        dx[1] = 0.0;
        return;
    }
    const double n_over_r = d->gear_ratio / d->drum_radius_m;
    const double mass_kg = d->motor_inertia_kgm2 * n_over_r * n_over_r +
                           d->drum_inertia_kgm2 / (d->drum_radius_m * d->drum_radius_m) +
                           d->belt_mass_kg + d->load_mass_kg;
    const double coulomb_N =
        d->coulomb_friction_N + d->load_friction_coefficient * GRAVITY_MPS2 * d->load_mass_kg;
    const double drive_N = forcePerAmpere(d) * current_A;
    const double friction_N = d->viscous_friction_Nspm * x[0] +
                              coulomb_N * tanh(x[0] / d->coulomb_smoothing_speed_mps);
    dx[0] = (drive_N - friction_N + d->perturbation_N) / mass_kg;
    dx[1] = x[0];
}

void calculateValues(ModelInstance *comp) {
    ModelData *d = &comp->data;
    bool stopped = false;
    if (closesBrake(d, comp->y)) { /* an output between grid points obeys the grid's rule */
        holdBelt(d, comp->y);
        stopped = d->speed_setpoint_mps == 0.0;
    }
    double command_A;
    d->motor_current_A = stopped ? 0.0 : motorCurrent(d, comp->y, &command_A);
    d->motor_torque_Nm = d->torque_constant_NmpA * d->motor_current_A;
}

Status getFloat64(ModelInstance *comp, ValueReference vr, double values[], size_t nValues,
                  size_t *index) {
    if (*index >= nValues) {
        logError(comp, "Get: too few values (%zu) for the value references.", nValues);
        return Error;
    }
    double value;
    switch (vr) {
    case vr_time: value = comp->time; break;
    case vr_belt_speed_mps: value = comp->y[0]; break;
    case vr_belt_position_m: value = comp->y[1]; break;
    case vr_motor_torque_Nm: value = comp->data.motor_torque_Nm; break;
    case vr_motor_current_A: value = comp->data.motor_current_A; break;
    case vr_speed_reference_mps: value = comp->data.reference_hold_mps; break;
    case vr_perturbation_force_N: value = comp->data.perturbation_N; break;
    default: {
        Float64Variable v;
        if (!float64Variable(comp, vr, &v)) {
            logError(comp, "Get: unknown Float64 value reference %u.", (unsigned)vr);
            return Error;
        }
        value = *v.field;
    }
    }
    values[(*index)++] = value;
    return OK;
}

Status setFloat64(ModelInstance *comp, ValueReference vr, const double values[], size_t nValues,
                  size_t *index) {
    if (*index >= nValues) {
        logError(comp, "Set: too few values (%zu) for the value references.", nValues);
        return Error;
    }
    Float64Variable v;
    if (!float64Variable(comp, vr, &v)) {
        logError(comp, "Set: Float64 value reference %u is not an input or parameter.",
                 (unsigned)vr);
        return Error;
    }
    if (v.isParameter && comp->state == StepMode) {
        logError(comp, "Set: parameter %s is fixed and cannot be set after initialization.",
                 v.name);
        return Error;
    }
    const double value = values[(*index)++];
    if (checkValue(comp, &v, value) > Warning) return Error;
    *v.field = value;
    return OK;
}

Status getInt32(ModelInstance *comp, ValueReference vr, int32_t values[], size_t nValues,
                size_t *index) {
    if (*index >= nValues) {
        logError(comp, "Get: too few values (%zu) for the value references.", nValues);
        return Error;
    }
    if (vr != vr_perturbation_seed) {
        logError(comp, "Get: unknown Int32 value reference %u.", (unsigned)vr);
        return Error;
    }
    values[(*index)++] = comp->data.perturbation_seed;
    return OK;
}

Status setInt32(ModelInstance *comp, ValueReference vr, const int32_t values[], size_t nValues,
                size_t *index) {
    if (*index >= nValues) {
        logError(comp, "Set: too few values (%zu) for the value references.", nValues);
        return Error;
    }
    if (vr != vr_perturbation_seed) {
        logError(comp, "Set: Int32 value reference %u is not a parameter.", (unsigned)vr);
        return Error;
    }
    if (comp->state == StepMode) {
        logError(comp, "Set: parameter perturbation_seed is fixed and cannot be set after "
                       "initialization.");
        return Error;
    }
    const int32_t value = values[(*index)++];
    if (value < 0) {
        logError(comp, "perturbation_seed = %d is invalid: perturbation_seed requires a value >= 0.",
                 (int)value);
        return Error;
    }
    comp->data.perturbation_seed = value;
    return OK;
}
