/* Thermal twin ROM: the model core shared by the FMI 2.0 and FMI 3.0 APIs (fmi2.c, fmi3.c).
 *
 * Not a translation unit of its own: fmi2.c / fmi3.c include it after defining ``Callbacks``
 * and including model_data.h (the generated ROM data), so the FMU compiles as one C file.
 * Each API defines ``emit`` (hand a message to the importer's logger) and ``alloc_instance``
 * (memory for an FMU state) and wraps the core in its functions.
 */
typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

typedef struct {
    char instance_name[256];
    Callbacks cb;
    int logging_on;
    Phase phase;
    double time;
    double t_initial;
    double spindle_factor;   /* tunable: factor on the spindle-driven sources' power */
    int steady_start;
    double in[N_FMU_INPUTS];
    double z[NZ];
    double u[NU];
    double y[NY];
    int y_valid;
    double h;        /* step size of a and g, 0 = none yet */
    double a[NZ];
    double g[NZ];
    double w[NLAG_ALLOC];          /* air of the lagged zones (degC), states of the model */
    double e[NLAG_ALLOC];          /* exp(-h / tau) per lagged zone */
    double E[NZ][NLAG_ALLOC];      /* cross term: how the lagged air drives each mode over a step */
} Instance;

static void emit(const Instance *inst, int is_error, const char *category, const char *message);
static void *alloc_instance(const Instance *inst);

static void vlog(const Instance *inst, int is_error, const char *category, const char *fmt, va_list ap) {
    char buf[1024];
    if (!inst || (!inst->logging_on && !is_error)) return;
    vsnprintf(buf, sizeof buf, fmt, ap);
    emit(inst, is_error, category, buf);
}

static void log_error(const Instance *inst, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, 1, "logStatusError", fmt, ap);
    va_end(ap);
}

static void log_info(const Instance *inst, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, 0, "logAll", fmt, ap);
    va_end(ap);
}

/* Start values, phase "instantiated" (instantiation and reset). */
static void set_defaults(Instance *inst) {
    int i;
    inst->phase = ST_INSTANTIATED;
    inst->time = 0.0;
    inst->t_initial = T_INITIAL_START;
    inst->spindle_factor = SPINDLE_FACTOR_START;
    inst->steady_start = STEADY_START_START;
    for (i = 0; i < N_FMU_INPUTS; i++) inst->in[i] = INPUT_START[i];
    for (i = 0; i < NZ; i++) inst->z[i] = 0.0;
    for (i = 0; i < NLAG; i++) inst->w[i] = 0.0;
    inst->h = 0.0;
    inst->y_valid = 0;
}

/* FMU inputs -> thermal inputs u */
static void thermal_inputs(Instance *inst) {
    int i;
    double rpm = fabs(inst->in[IN_RPM]);
    double fx = fabs(inst->in[IN_FEED_X]), fy = fabs(inst->in[IN_FEED_Y]), fz = fabs(inst->in[IN_FEED_Z]);
    for (i = 0; i < NU; i++) inst->u[i] = U_FROM_INPUT[i] >= 0 ? inst->in[U_FROM_INPUT[i]] : 0.0;
    for (i = 0; i < N_SOURCES; i++) {
        double n;
        switch (SRC_DRIVER[i]) {
            case 0: n = SRC_REF[i]; break;                       /* constant */
            case 1: n = rpm; break;                              /* spindle */
            case 2: n = fx; break;
            case 3: n = fy; break;
            case 4: n = fz; break;
            case 5: n = fx > fy ? fx : fy; break;                /* feed_xy */
            default: n = fx > fy ? (fx > fz ? fx : fz) : (fy > fz ? fy : fz); break;
        }
        inst->u[SRC_U_INDEX[i]] = SRC_COEF[i] * pow(n / SRC_REF[i], SRC_EXP[i]);
        if (SRC_DRIVER[i] == 1) inst->u[SRC_U_INDEX[i]] *= inst->spindle_factor;
    }
    for (i = 0; i < NLAG; i++) inst->u[LAG_U_INDEX[i]] = inst->w[i];   /* the lagged zones' air: states */
}

/* The lagged zones' air in equilibrium with the room: their value at a start. */
static void lags_at_room(Instance *inst) {
    int i;
    for (i = 0; i < NLAG; i++) inst->w[i] = inst->in[IN_ROOM];
}

static void compute_outputs(Instance *inst) {
    int i, j;
    thermal_inputs(inst);
    for (i = 0; i < NY; i++) {
        double s = OFFSET[i];
        for (j = 0; j < NZ; j++) s += CZ[i][j] * inst->z[j];
        for (j = 0; j < NU; j++) s += DZ[i][j] * inst->u[j];
        inst->y[i] = s;
    }
    inst->y_valid = 1;
}

/* ``x`` in as few digits as read back to the same double (15, else 17): a message must not say
   "12000 is outside [0, 12000]" of 12000.000000000002. */
static const char *exact(char buf[32], double x) {
    snprintf(buf, 32, "%.15g", x);
    if (strtod(buf, NULL) != x) snprintf(buf, 32, "%.17g", x);
    return buf;
}

/* Values this far outside a bound, relative to the range, are rounding — fmpy's interpolation of a
   constant 12000 rpm gives 12000.000000000002 — and are taken as the bound. */
#define RANGE_TOLERANCE 1e-9

/* Whether ``*x`` may be given to ``name`` (range [lo, hi]): 1, with *x clipped onto the range when it is
   outside by rounding only; 0 (logged, naming the variable and the value) for a non-finite value or one
   outside the range. */
static int accept_value(const Instance *inst, const char *api, const char *name, double *x, double lo,
                        double hi) {
    char v[32], a[32], b[32];
    double margin = RANGE_TOLERANCE * (hi - lo);
    if (!isfinite(*x)) {
        log_error(inst, "%s: %s = %s is not a finite number", api, name, exact(v, *x));
        return 0;
    }
    if (*x < lo - margin || *x > hi + margin) {
        log_error(inst, "%s: %s = %s is outside [%s, %s]", api, name, exact(v, *x), exact(a, lo), exact(b, hi));
        return 0;
    }
    *x = *x < lo ? lo : (*x > hi ? hi : *x);
    return 1;
}

static void start_state(Instance *inst) {
    int i, j;
    lags_at_room(inst);
    thermal_inputs(inst);
    for (i = 0; i < NZ; i++) {
        if (inst->steady_start) {
            double s = 0.0;
            for (j = 0; j < NU; j++) s += BZ[i][j] * inst->u[j];
            inst->z[i] = s / LAMBDA[i];
        } else {
            inst->z[i] = inst->t_initial * UNIFORM[i];
        }
    }
    inst->y_valid = 0;
}

/* One exact zero-order-hold step of h; returns 1 when the coefficients were recomputed.
 * Each lagged zone's air follows the held room value r exactly, w <- r + (w - r) e^{-h/tau}; it drives
 * mode i by B_il w(t), whose part r is in g and whose decaying part (w - r) e^{-t/tau} gives the cross
 * term E_il = int_0^h e^{-lambda_i (h - s)} e^{-s/tau} ds = (e^{-h/tau} - e^{-lambda_i h}) / (lambda_i - 1/tau). */
static int zoh_step(Instance *inst, double h) {
    int i, j, l, changed = 0;
    double room;
    if (h != inst->h) {
        for (i = 0; i < NZ; i++) {
            inst->a[i] = exp(-LAMBDA[i] * h);
            inst->g[i] = -expm1(-LAMBDA[i] * h) / LAMBDA[i];
            for (l = 0; l < NLAG; l++) {   /* written without cancellation, also for lambda_i = 1/tau */
                double d = fabs(LAMBDA[i] - LAG_MU[l]);
                double slow = LAMBDA[i] < LAG_MU[l] ? LAMBDA[i] : LAG_MU[l];
                inst->E[i][l] = (d == 0.0 ? h : -expm1(-d * h) / d) * exp(-slow * h);
            }
        }
        for (l = 0; l < NLAG; l++) inst->e[l] = exp(-LAG_MU[l] * h);
        changed = inst->h != 0.0;
        inst->h = h;
    }
    thermal_inputs(inst);
    room = inst->in[IN_ROOM];
    for (l = 0; l < NLAG; l++) inst->u[LAG_U_INDEX[l]] = room;
    for (i = 0; i < NZ; i++) {
        double w = 0.0;
        for (j = 0; j < NU; j++) w += BZ[i][j] * inst->u[j];
        inst->z[i] = inst->a[i] * inst->z[i] + inst->g[i] * w;
        for (l = 0; l < NLAG; l++) inst->z[i] += inst->E[i][l] * BZ[i][LAG_U_INDEX[l]] * (inst->w[l] - room);
    }
    for (l = 0; l < NLAG; l++) inst->w[l] = room + (inst->w[l] - room) * inst->e[l];
    inst->y_valid = 0;
    return changed;
}

/* Parameters (T_initial, steady_start) can be set until initialisation ends. */
static int parameters_settable(const Instance *inst) {
    return inst->phase == ST_INSTANTIATED || inst->phase == ST_INIT;
}

/* End of initialisation: set the start state (every value was checked when it was set). */
static void exit_initialization(Instance *inst) {
    start_state(inst);
    inst->phase = ST_STEP;
}

/* Whether a step may start at t: the FMU's time (the start time plus the steps made, or that of a
   restored FMU state).  The slack is rounding in the master's own sum of steps: 1e-6 of the step, and
   1e-12 of t for long runs. */
static int at_current_time(const Instance *inst, double t, double h) {
    return fabs(t - inst->time) <= 1e-6 * h + 1e-12 * fabs(inst->time);
}

/* A communication step of h from t (``api``: the calling function, for messages); 1 done, 0 (logged)
   refused — before initialisation or after termination, a step that is not positive and finite, or a t
   that is not the FMU's time.  The inputs need no check here: each was checked when it was set. */
static int do_step(Instance *inst, const char *api, double t, double h) {
    char when[96], a[32], b[32];
    double previous = inst->h;
    snprintf(when, sizeof when, "%s at t = %s s", api, exact(a, t));
    if (inst->phase != ST_STEP) {
        log_error(inst, "%s: the FMU is not initialised", when);
        return 0;
    }
    if (!(h > 0.0) || !isfinite(h)) {
        log_error(inst, "%s: step size %s must be positive and finite", when, exact(a, h));
        return 0;
    }
    if (!at_current_time(inst, t, h)) {
        log_error(inst, "%s: the FMU is at t = %s s; a step starts where the last one ended (or at the time of "
                  "a state restored with SetFMUstate)", when, exact(b, inst->time));
        return 0;
    }
    if (zoh_step(inst, h))   /* exact ZOH coefficients for this step size */
        log_info(inst, "%s: step size changed from %g s to %g s; ZOH coefficients recomputed", when, previous, h);
    inst->time = t + h;
    return 1;
}

/* Real (Float64) variables by value reference; 0 (logged) on failure. */
static int get_real(Instance *inst, unsigned r, double *value, const char *api, const char *type) {
    if (r == VR_T_INITIAL) *value = inst->t_initial;
    else if (r == VR_SPINDLE_FACTOR) *value = inst->spindle_factor;
    else if (r >= VR_INPUT0 && r < VR_INPUT0 + N_FMU_INPUTS) *value = inst->in[r - VR_INPUT0];
    else if (r >= VR_OUTPUT0 && r < VR_OUTPUT0 + NY) {
        if (!inst->y_valid) {
            /* Before the first step (Instantiated / Initialization Mode) the outputs are those of the
               start state the parameters and inputs imply, as after fmi2ExitInitializationMode. */
            if (parameters_settable(inst)) start_state(inst);
            compute_outputs(inst);
        }
        *value = inst->y[r - VR_OUTPUT0];
    } else {
        log_error(inst, "%s: no %s variable has value reference %u", api, type, r);
        return 0;
    }
    return 1;
}

/* Set a Real (Float64) variable by value reference; 0 (logged) when refused: a fixed parameter after
   initialisation, or a value ``accept_value`` refuses (the variable keeps its value). */
static int set_real(Instance *inst, unsigned r, double value, const char *api, const char *type) {
    if (r == VR_T_INITIAL) {
        if (!parameters_settable(inst)) {
            log_error(inst, "%s: T_initial is a fixed parameter: it can only be set before initialisation ends",
                      api);
            return 0;
        }
        if (!accept_value(inst, api, "T_initial", &value, T_INITIAL_MIN, T_INITIAL_MAX)) return 0;
        inst->t_initial = value;
    } else if (r == VR_SPINDLE_FACTOR) {   /* tunable: any time, within its range */
        if (!accept_value(inst, api, "spindle_power_factor", &value, SPINDLE_FACTOR_MIN, SPINDLE_FACTOR_MAX))
            return 0;
        inst->spindle_factor = value;
    } else if (r >= VR_INPUT0 && r < VR_INPUT0 + N_FMU_INPUTS) {
        unsigned i = r - VR_INPUT0;
        if (!accept_value(inst, api, INPUT_NAME[i], &value, INPUT_MIN[i], INPUT_MAX[i])) return 0;
        inst->in[i] = value;
    } else {
        log_error(inst, "%s: value reference %u is not a settable %s", api, r, type);
        return 0;
    }
    inst->y_valid = 0;
    return 1;
}

/* ``bytes`` (default: the instance itself) copied into ``state`` (allocated when NULL), with this
   process's callbacks; NULL when out of memory. */
static Instance *store_state(const Instance *inst, void *state, const void *bytes) {
    Instance *copy = (Instance *)(state ? state : alloc_instance(inst));
    if (!copy) return NULL;
    memcpy(copy, bytes ? bytes : (const void *)inst, sizeof(Instance));
    copy->cb = inst->cb;     /* callbacks belong to this process */
    return copy;
}
