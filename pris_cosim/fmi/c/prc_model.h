/* Description of one generated network FMU, filled in by the generated model.c.
 *
 * The network tables mirror pris_cosim.mna.MNA: node indices (-1 = ground),
 * the constant bases Q0 / Q1 of the algebraic and capacitive node-voltage
 * subspaces, and the input maps BI (current inputs) and BV (voltage inputs).
 * At run time prc_network.c assembles G, Cn and L from the element values
 * and eliminates the algebraic variables exactly as mna.py does.
 */
#ifndef PRC_MODEL_H
#define PRC_MODEL_H

#define PRC_GROUND (-1)

/* One element: value in Real variable `slot`; nodes a, b (R, L, C) or
 * inductor indices a, b (K); `expr` is the tie text or NULL. */
typedef struct {
    const char *name;
    int slot;
    int a, b;
    const char *expr;
} prc_elem;

enum { PRC_OUT_NODE = 0, PRC_OUT_STATE = 1, PRC_OUT_INPUT = 2 };

/* An FMU output: Real variable vr = node voltage / state / input number index. */
typedef struct {
    int vr;
    int kind;
    int index;
} prc_output;

/* When a variable may be set: never, before the end of initialisation, always. */
enum { PRC_SET_NEVER = 0, PRC_SET_INIT = 1, PRC_SET_ALWAYS = 2 };

typedef struct {
    const char *guid;
    /* Real and Integer variables by value reference */
    int n_real;
    const double *real_start;
    const char *const *real_names;
    const unsigned char *real_settable;
    const double *real_min, *real_max;  /* declared range (+-HUGE_VAL: none) */
    const double *state_nominal;        /* nominal value per state */
    int n_int;
    const int *int_start;
    const char *const *int_names;
    const unsigned char *int_settable;
    const int *int_min, *int_max;
    /* network */
    int n_nodes;
    int n_r, n_c, n_l, n_k, n_v;
    const prc_elem *resistors, *capacitors, *inductors, *couplings;
    const int *v_nodes;        /* 2 * n_v */
    int n_q0, n_q1;
    const double *Q0, *Q1;     /* n_nodes x n_q0, n_nodes x n_q1, row-major */
    int n_ui, n_uv;
    const double *BI, *BV;     /* n_nodes x n_ui, n_v x n_uv */
    const int *input_vr;       /* per input: Real vr of the FMU input, -1 for the bridge */
    int bridge_input;          /* input index of the H-bridge voltage, -1 if none */
    int vr_state0, vr_deriv0;  /* first vr of the nx states and of their derivatives */
    int n_out;
    const prc_output *outputs;
    int vr_vdc, vr_fclk;       /* Real vrs of the source settings, -1 without bridge */
    int ivr_order, ivr_seed;   /* Integer vrs of PRBS order and seed, -1 without bridge */
    const unsigned int *prbs_taps;  /* tap mask per order 0..32 (bit t-1 set for tap t) */
    double max_switches;            /* most PRBS switching instants one experiment may hold */
    void (*compute)(double *r);     /* evaluate parameter ties in dependency order */
} prc_model;

extern const prc_model PRC_MODEL;

#endif
