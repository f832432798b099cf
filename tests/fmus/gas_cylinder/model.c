/* A passive gas-charged cylinder: F = A p - c v with the head side's gauge pressure
   p = p0 (V0 / V)^n - p_atm, V = V0 + A (x - s_ref), the state x the cylinder's own stroke
   (dx/dt = v); its rod side is open to the atmosphere. Static force law: F(s) at v = 0. */
#include <math.h>
#include "config.h"
#include "model.h"

Status setStartValues(ModelInstance *comp) {
    M(stroke) = 0.05;
    M(velocity) = 0.0;
    M(x) = 0.05;
    M(area) = 2.0e-3;
    M(p0) = 6.6e6;
    M(V0) = 1.2e-4;
    M(s_ref) = 0.05;
    M(n) = 1.4;
    M(c) = 1.4e4;
    M(p_atm) = 1.0e5;
    M(fail_time) = 1e30;
    M(nan_time) = 1e30;
    comp->isDirtyValues = true;
    return OK;
}

static double volume(ModelInstance *comp) {
    return M(V0) + M(area) * (M(x) - M(s_ref));
}

Status calculateValues(ModelInstance *comp) {
    if (comp->time >= M(fail_time)) {
        logError(comp, "injected failure at t = %g s", comp->time);
        return Error;
    }
    double V = volume(comp);
    M(pressure) = M(p0) * pow(M(V0) / V, M(n)) - M(p_atm);
    M(force) = M(area) * M(pressure) - M(c) * M(velocity);
    if (comp->time >= M(nan_time)) M(force) = NAN;
    M(power) = M(force) * M(velocity);
    comp->isDirtyValues = false;
    return OK;
}

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues,
                  size_t* index) {
    Status status = calculateValues(comp);
    if (status > Warning) return status;
    double *v = values + *index;
    ASSERT_NVALUES(1);
    switch (vr) {
        case vr_time: *v = comp->time; break;
        case vr_stroke: *v = M(stroke); break;
        case vr_velocity: *v = M(velocity); break;
        case vr_x: *v = M(x); break;
        case vr_der_x: *v = M(velocity); break;
        case vr_force: *v = M(force); break;
        case vr_power: *v = M(power); break;
        case vr_area: *v = M(area); break;
        case vr_p0: *v = M(p0); break;
        case vr_V0: *v = M(V0); break;
        case vr_s_ref: *v = M(s_ref); break;
        case vr_n: *v = M(n); break;
        case vr_c: *v = M(c); break;
        case vr_p_atm: *v = M(p_atm); break;
        case vr_fail_time: *v = M(fail_time); break;
        case vr_nan_time: *v = M(nan_time); break;
        case vr_pressure: *v = M(pressure); break;
        case vr_stroke_mm: *v = 1e3 * M(stroke); break;
        case vr_velocity_mm_s: *v = 1e3 * M(velocity); break;
        case vr_force_kN: *v = 1e-3 * M(force); break;
        case vr_pressure_MPa: *v = 1e-6 * M(pressure); break;
        default:
            logError(comp, "Get Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
    (*index)++;
    return OK;
}

Status setFloat64(ModelInstance* comp, ValueReference vr, const double values[],
                  size_t nValues, size_t* index) {
    ASSERT_NVALUES(1);
    double v = values[(*index)++];
    bool initialising = comp->state == Instantiated || comp->state == InitializationMode;
    switch (vr) {
        case vr_stroke:
            M(stroke) = v;
            if (initialising) M(x) = v;   /* the state starts at the stroke it is given */
            break;
        case vr_stroke_mm:
            M(stroke) = 1e-3 * v;
            if (initialising) M(x) = M(stroke);
            break;
        case vr_velocity: M(velocity) = v; break;
        case vr_velocity_mm_s: M(velocity) = 1e-3 * v; break;
        case vr_area: M(area) = v; break;
        case vr_p0: M(p0) = v; break;
        case vr_V0: M(V0) = v; break;
        case vr_s_ref: M(s_ref) = v; break;
        case vr_n: M(n) = v; break;
        case vr_c: M(c) = v; break;
        case vr_p_atm: M(p_atm) = v; break;
        case vr_fail_time: M(fail_time) = v; break;
        case vr_nan_time: M(nan_time) = v; break;
        default:
            logError(comp, "Set Float64 is not allowed for value reference %u.", vr);
            return Error;
    }
    comp->isDirtyValues = true;
    return OK;
}

size_t getNumberOfContinuousStates(ModelInstance* comp) {
    UNUSED(comp);
    return 1;
}

Status getContinuousStates(ModelInstance *comp, double x[], size_t nx) {
    UNUSED(nx);
    x[0] = M(x);
    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    UNUSED(comp);
    UNUSED(nx);
    nominals[0] = 0.1;
    return OK;
}

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    UNUSED(nx);
    M(x) = x[0];
    comp->isDirtyValues = true;
    return OK;
}

Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    UNUSED(nx);
    Status status = calculateValues(comp);
    if (status > Warning) return status;
    dx[0] = M(velocity);
    return OK;
}

#ifdef GET_PARTIAL_DERIVATIVE
Status getPartialDerivative(ModelInstance *comp, ValueReference unknown, ValueReference known,
                            double *partialDerivative) {
    calculateValues(comp);
    double V = volume(comp);
    double dF_dx = -M(n) * M(area) * M(area) * M(p0) * pow(M(V0) / V, M(n)) / V;
    double d = 0.0, scale = 1.0;   /* the variables in mm/s and kN: SI's partials scaled */
    if (known == vr_velocity_mm_s) { known = vr_velocity; scale *= 1e-3; }
    if (unknown == vr_force_kN) { unknown = vr_force; scale *= 1e-3; }
    if (unknown == vr_der_x && known == vr_velocity) d = 1.0;
    else if (unknown == vr_force && known == vr_x) d = dF_dx;
    else if (unknown == vr_force && known == vr_velocity) d = -M(c);
    else if (unknown == vr_power && known == vr_x) d = dF_dx * M(velocity);
    else if (unknown == vr_power && known == vr_velocity) d = M(force) - M(c) * M(velocity);
    *partialDerivative = scale * d;
    return OK;
}
#endif
