"""FQI's and LSPI's sweeps over the database (thesis 3.3, Alg. 6). A binary design matrix Phi (n, f) over the f
weights a data set touches is given by its active ``columns`` (n, N): row d has a one at each columns[d, k] (a column
repeated within a row, a hash collision, counts twice)."""

from sb3_er.common.kernels._jit import kernel
from sb3_er.common.kernels.policy import argmax_first
from sb3_er.common.kernels.tiles import all_q_values


@kernel
def greedy_next_values(theta, next_slots, terminal, layout, q_scratch, out_values, out_actions):
    """max_a Q(s'_d, a) and its argmax (lowest index on ties) for each transition d (FQI's Eq. 3.1, LSPI's greedy
    policy at s'); 0 and -1 where s'_d is terminal.

    :param theta: the weights (Weights.theta).
    :param next_slots: the slots of each s'_d, (n, N).
    :param terminal: whether each s'_d is terminal, (n,).
    :param layout: the TileLayout.
    :param q_scratch: scratch for Q(s', .), float64 (A,).
    :param out_values: written: max_a Q(s'_d, a), (n,).
    :param out_actions: written: the greedy action of each row, (n,).
    """
    for d in range(next_slots.shape[0]):
        if terminal[d]:
            out_values[d] = 0.0
            out_actions[d] = -1
            continue
        all_q_values(theta, next_slots[d], layout, q_scratch)
        best = argmax_first(q_scratch)
        out_values[d] = q_scratch[best]
        out_actions[d] = best


@kernel
def features_dot(x, columns, out):
    """out = Phi x: out[d] = sum_k x[columns[d, k]] (the fitted values of the n samples).

    :param x: the weights of the fit, (features,).
    :param columns: the active feature columns of each sample, (n, N).
    :param out: written: Phi x, (n,).
    """
    for d in range(columns.shape[0]):
        total = 0.0
        for k in range(columns.shape[1]):
            total += x[columns[d, k]]
        out[d] = total


@kernel
def features_transpose_dot(y, columns, out):
    """out = Phi^T y: out[j] = sum of y[d] over the samples d with feature j active (with multiplicity).

    :param y: one value per sample, (n,).
    :param columns: the active feature columns of each sample, (n, N).
    :param out: written: Phi^T y, (features,).
    """
    for j in range(out.shape[0]):
        out[j] = 0.0
    for d in range(columns.shape[0]):
        for k in range(columns.shape[1]):
            out[columns[d, k]] += y[d]


@kernel
def ridge_normal_matvec(x, columns, ridge, out):
    """out = (Phi^T Phi + ridge I) x: the matrix of the ridge normal equations of FQI's least-squares fit.

    :param x: a weight vector, (features,).
    :param columns: the active feature columns of each sample, (n, N).
    :param ridge: the ridge term lambda.
    :param out: written: the product, (features,).
    """
    for j in range(out.shape[0]):
        out[j] = ridge * x[j]
    for d in range(columns.shape[0]):
        total = 0.0
        for k in range(columns.shape[1]):
            total += x[columns[d, k]]
        for k in range(columns.shape[1]):
            out[columns[d, k]] += total
