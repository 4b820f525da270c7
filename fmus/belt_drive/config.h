/* BeltDrive: a conveyor belt driven by a PI speed-controlled motor through a gearbox, with a
 * setpoint ramp and a holding brake (a non-reversing conveyor drive). */
#ifndef BELT_DRIVE_CONFIG_H
#define BELT_DRIVE_CONFIG_H

#include <stdbool.h>
#include <stdint.h>

#define MODEL_IDENTIFIER BeltDrive
#define INSTANTIATION_TOKEN "{5d3c8f2e-6a41-4b7e-9c0d-1e2f3a4b5c6d}"

/* Continuous states: belt speed (m/s), belt position (m), PI integral term (A). */
#define NX 3

typedef enum {
    vr_time = 0,
    vr_torque_constant_NmpA = 1,
    vr_current_limit_A = 2,
    vr_speed_gain_Aspm = 3,
    vr_integral_gain_Apm = 4,
    vr_antiwindup_time_s = 5,
    vr_gear_ratio = 6,
    vr_drum_radius_m = 7,
    vr_motor_inertia_kgm2 = 8,
    vr_drum_inertia_kgm2 = 9,
    vr_belt_mass_kg = 10,
    vr_viscous_friction_Nspm = 11,
    vr_coulomb_friction_N = 12,
    vr_load_friction_coefficient = 13,
    vr_coulomb_smoothing_speed_mps = 14,
    vr_perturbation_std_N = 15,
    vr_perturbation_correlation_time_s = 16,
    vr_perturbation_seed = 17,
    vr_setpoint_ramp_limit_mps2 = 18,
    vr_internal_step_s = 19,
    vr_setpoint_weight = 20,
    vr_standstill_speed_mps = 21,
    vr_speed_setpoint_mps = 30,
    vr_load_mass_kg = 31,
    vr_belt_speed_mps = 40,
    vr_belt_position_m = 41,
    vr_motor_torque_Nm = 42,
    vr_motor_current_A = 43,
    vr_speed_reference_mps = 50,
    vr_perturbation_force_N = 51
} ValueReference;

typedef struct {
    double torque_constant_NmpA;
    double current_limit_A;
    double speed_gain_Aspm;
    double integral_gain_Apm;
    double antiwindup_time_s;
    double gear_ratio;
    double drum_radius_m;
    double motor_inertia_kgm2;
    double drum_inertia_kgm2;
    double belt_mass_kg;
    double viscous_friction_Nspm;
    double coulomb_friction_N;
    double load_friction_coefficient;
    double coulomb_smoothing_speed_mps;
    double perturbation_std_N;
    double perturbation_correlation_time_s;
    int32_t perturbation_seed;
    double setpoint_ramp_limit_mps2;
    double internal_step_s;
    double setpoint_weight;
    double standstill_speed_mps;
    double speed_setpoint_mps;
    double load_mass_kg;
    double motor_current_A;
    double motor_torque_Nm;
    double reference_mps;
    double reference_hold_mps;
    double perturbation_N;
    bool brake_closed;                /* brake state at the last grid point */
    bool brake_hold;                  /* brake state over the current grid interval */
    double interval_start_position_m; /* belt position at the start of that interval */
    double ou_decay;
    double ou_diffusion_N;
    uint64_t rng[4];
} ModelData;

#endif
