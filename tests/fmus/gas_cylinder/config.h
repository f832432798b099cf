#ifndef config_h
#define config_h

/* A passive gas-charged tensioning cylinder: the test FMU of trackmj's FMI import. */
#define MODEL_IDENTIFIER GasCylinder
#define INSTANTIATION_TOKEN "{6f1c2a52-3c1d-4c55-9d4e-2f0b9a7e1c11}"

#define CO_SIMULATION
#define MODEL_EXCHANGE

#define MAX_CONTINUOUS_STATES 1

#define SET_FLOAT64

#define FIXED_SOLVER_STEP 1e-4
#define DEFAULT_STOP_TIME 1

typedef enum {
    vr_time, vr_stroke, vr_velocity, vr_x, vr_der_x, vr_force, vr_power,
    vr_area, vr_p0, vr_V0, vr_s_ref, vr_n, vr_c, vr_p_atm, vr_fail_time, vr_nan_time,
    vr_pressure, vr_stroke_mm, vr_velocity_mm_s, vr_force_kN, vr_pressure_MPa
} ValueReference;

typedef struct {
    double stroke;     /* input: stroke at the end of the step [m] */
    double velocity;   /* input: stroke velocity [m/s] */
    double x;          /* state: the cylinder's own stroke, dx/dt = velocity [m] */
    double force;      /* output: force on the idler, > 0 outward [N] */
    double power;      /* output: mechanical port power force * velocity [W] */
    double area;       /* gas piston area [m2] */
    double p0;         /* gas pressure at s_ref, absolute [Pa] */
    double V0;         /* gas volume at s_ref [m3] */
    double s_ref;      /* stroke of p0 and V0 [m] */
    double n;          /* polytropic exponent [-] */
    double c;          /* viscous damping [N s/m] */
    double p_atm;      /* ambient pressure on the rod side [Pa] */
    double fail_time;  /* from this time on every evaluation fails (test of errors) [s] */
    double nan_time;   /* from this time on the force is NaN (test of the guards) [s] */
    double pressure;   /* output: gas pressure less p_atm, the head side's gauge pressure [Pa] */
    /* stroke_mm, velocity_mm_s (inputs), force_kN, pressure_MPa (outputs): stroke,
       velocity, force and pressure in mm, mm/s, kN and MPa (tests of declared units) */
} ModelData;

#endif /* config_h */
