"""The numba kernels: everything that runs per update, reading like the thesis pseudocode (equation and algorithm
numbers refer to the thesis), one module per concern:

- :mod:`~sb3_er.common.kernels.bundles`: the argument bundles (tile layout, weights, stored data, update rule, trace,
  scratch space...), each documented once, and the enumerations they carry;
- :mod:`~sb3_er.common.kernels.rng`: seeded xoshiro256** generators passed in as state arrays;
- :mod:`~sb3_er.common.kernels.tiles`: tile slots (Eq. 2.9), Q(s, a) (Eq. 2.8), visit counts (Eq. 5.1-5.2), initial
  weights;
- :mod:`~sb3_er.common.kernels.policy`: greedy and epsilon-greedy action choice;
- :mod:`~sb3_er.common.kernels.watch`: the value watch;
- :mod:`~sb3_er.common.kernels.sarsa`: Sarsa(lambda) (Alg. 2);
- :mod:`~sb3_er.common.kernels.replay`: ER, ER-sigma, residual ER and residual ER-sigma (Alg. 8, 10, 12, 14) and the
  replay phase;
- :mod:`~sb3_er.common.kernels.prioritized`: prioritized sweeping;
- :mod:`~sb3_er.common.kernels.batch`: FQI's and LSPI's sweeps;
- :mod:`~sb3_er.common.kernels.dyna`: Dyna's step.

Conventions shared by all kernels: Q(s, a) = the sum of the N active weights (Eq. 2.8), and a learning rate alpha on
Q moves each active weight by alpha / N (``UpdateRule.step_size``). Random numbers come from generator states passed
in. Kernels allocate nothing and hold no Python object, so they run without the GIL. A replay phase, a fit's sweep or
an environment step is one kernel call.
"""

from sb3_er.common.kernels.batch import features_dot, features_transpose_dot, greedy_next_values, ridge_normal_matvec
from sb3_er.common.kernels.bundles import (
    BUNDLES,
    ORDER_FORWARD,
    ORDER_PRIORITIZED,
    ORDER_REVERSED,
    ORDER_UNIFORM,
    PREDECESSORS_TILES,
    PREDECESSORS_TRAJECTORY,
    SIGMA_AVERAGE,
    SIGMA_AVERAGE_BEST,
    SIGMA_AVERAGE_WORST,
    SIGMA_BEST,
    SIGMA_NONE,
    SIGMA_WORST,
    STATUS_BAD_OBSERVATION,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_OUT_OF_BOUNDS,
    STATUS_TRACE_FULL,
    TARGET_EXPECTED_SARSA,
    TARGET_Q_LEARNING,
    TARGET_SARSA,
    Plan,
    PriorityQueue,
    Replay,
    Scratch,
    Sweep,
    TargetCopy,
    TileLayout,
    Trace,
    Trajectories,
    Transition,
    UpdateRule,
    Weights,
    make,
    update_rule,
    weights_bundle,
)
from sb3_er.common.kernels.dyna import dyna_step
from sb3_er.common.kernels.policy import batch_q_values, greedy_actions, select_action
from sb3_er.common.kernels.prioritized import (
    build_predecessor_index,
    heap_clear,
    heap_heapify,
    heap_pop,
    heap_remove,
    heap_set,
    prioritized_phase,
)
from sb3_er.common.kernels.replay import replay_phase
from sb3_er.common.kernels.rng import (
    RNG_STREAM_ACTIONS,
    RNG_STREAM_PLANNING,
    RNG_STREAM_PREDICT,
    RNG_STREAM_REPLAY,
    new_rng_state,
)
from sb3_er.common.kernels.sarsa import clear_trace, sarsa_lambda_step
from sb3_er.common.kernels.tiles import (
    MAX_TILE_COORDINATE,
    batch_state_slots,
    fill_initial_weights,
    initial_weights_at,
    mark_visited,
    mark_visited_tracked,
    refresh_target,
    state_slots,
    weight_statistics,
)
from sb3_er.common.kernels.watch import (
    NO_WATCH,
    WATCH_BOUND_HIGH,
    WATCH_BOUND_LOW,
    WATCH_EXCURSION,
    WATCH_FIRST_UPDATE,
    WATCH_FIRST_VALUE,
    WATCH_HIGH,
    WATCH_LOW,
    WATCH_LOWERED,
    WATCH_OUT_OF_RANGE,
    WATCH_PERIOD,
    WATCH_PERIOD_UPDATES,
    WATCH_PROJECTED,
    WATCH_Q_MAX,
    WATCH_Q_MIN,
    WATCH_RAISED,
    WATCH_SHIFT_COUNT,
    WATCH_SHIFT_SUM,
    WATCH_SIZE,
    WATCH_TARGET_MAX,
    WATCH_TARGET_MIN,
    WATCH_TRUNCATED,
    WATCH_UPDATES,
    new_watch,
    reset_watch_period,
    set_watch_bounds,
    watch_batch,
)

#: (initial_low, initial_span, initial_seed) of all-zero initial weights, the thesis's theta <- 0.
ZERO_INITIAL = (0.0, 0.0, 0)
