"""Fitted Q-iteration with a linear projection on the tile features (Ernst et al. 2005; thesis 3.3.1, Alg. 6)."""

from typing import Any

import numpy as np
from scipy.sparse.linalg import LinearOperator, cg
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_er.common import kernels
from sb3_er.common.batch import FittedTileQAlgorithm, TileFeatures, Transitions, features_summary
from sb3_er.common.checks import check_bool, check_integer, check_number
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.policies import TileQPolicy


@inherit_parameters
class FQI(FittedTileQAlgorithm):
    """Fitted Q-iteration: E sweeps of targets T_d = r_d + gamma max_a Q(s'_d, a) (Eq. 3.1; T_d = r_d if s'_d is
    terminal) over the whole database, each followed by a least-squares projection of T onto the tile features
    (Alg. 6, Eq. 3.8-3.9):

        theta <- argmin_theta  sum_d (T_d - phi(s_d, a_d) . theta)^2 + ridge * ||theta - theta_0||^2

    over the f weights the data touches, the ridge pulling towards the initial weights theta_0 (the policy's
    ``initial_value``, 0 by default); every other weight keeps its initial value, so Q depends on the data alone.
    The fit runs every ``fit_every`` episodes; in between the agent acts epsilon-greedily on Q without learning.

    Solver: the ridge normal equations (Phi^T Phi + ridge I) theta = Phi^T T + ridge theta_0 by conjugate gradients
    (``scipy.sparse.linalg.cg``), matrix-free (two numba passes over the (n, N) active columns per product, never
    forming the f x f matrix) and Jacobi-preconditioned by the feature counts. A direct sparse factorisation does not
    scale: on the pendulum's data (150,000 transitions, 16 tilings) f reaches 380,000 and SuperLU's fill explodes.
    CG is warm-started from the current weights, and since successive sweeps' targets differ little, a few CG
    iterations per sweep (``solver_iterations``) suffice: each inexact solve continues from the previous one, so the
    fit converges over the sweeps (raise solver_iterations for an exact projection per sweep). Sweeps continue
    across fits (the first sweep of a fit bootstraps from the weights of the previous fit), so the optimisation
    horizon (thesis 3.5.4: E sweeps = an E-step horizon) grows by ``n_iterations`` with every fit; set
    ``warm_start=False`` for Ernst's restart from the initial Q_0 at every fit.

    Cost per sweep: O(n N A) for the targets plus O(n N) per CG iteration (thesis 3.5.4: O(nEi)).

    The ridge term matters beyond regularity: overlapping tilings leave directions of theta that the data does not
    determine (tilings disagreeing by opposite amounts), and Q(s', a) at tile combinations the data never showed reads
    them. Without enough ridge the max of Eq. 3.1 picks such extrapolated values and FQI diverges (Gordon 1995: a
    least-squares fit is no averager); on MountainCar, ridge 0.01 diverged where 1 did not.

    Defaults: every 5 episodes, 10 sweeps of at most 5 CG iterations, ridge 1 (see benchmarks/framework_cost.py).

    :param fit_every: episodes between fits (default 5).
    :param n_iterations: E, sweeps per fit (>= 1).
    :param ridge: lambda of the ridge term (> 0), in units of squared feature activations: a weight active in c samples
        is shrunk by about c N / (c N + lambda) with N tilings.
    :param solver_iterations: maximum conjugate-gradient iterations per sweep.
    :param solver_tolerance: CG stops when ||residual|| <= solver_tolerance * ||Phi^T T||.
    :param warm_start: start each fit's sweeps from the current Q (True) or from the initial Q (False, Ernst et al.).
    :param buffer_size: transitions kept; the oldest whole trajectories are evicted beyond it.
    :param learning_rate: not used: every fit solves its least-squares problem exactly.
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        fit_every: int = 5,
        n_iterations: int = 10,
        ridge: float = 1.0,
        solver_iterations: int = 5,
        solver_tolerance: float = 1e-6,
        warm_start: bool = True,
        buffer_size: int = 1_000_000,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
        trace_lambda: float | None = None,
        trace_cutoff: float = 0.01,
        value_watch: bool = True,
        value_bound_action: str = "warn",
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: str = "cpu",
        _init_setup_model: bool = True,
    ):
        self.solver_iterations = solver_iterations
        self.solver_tolerance = solver_tolerance
        self.warm_start = warm_start
        super().__init__(
            policy,
            env,
            fit_every=fit_every,
            n_iterations=n_iterations,
            ridge=ridge,
            buffer_size=buffer_size,
            replay_buffer_kwargs=replay_buffer_kwargs,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_lambda=trace_lambda,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

    def _check_hyperparameters(self) -> None:
        super()._check_hyperparameters()
        check_integer("solver_iterations", self.solver_iterations, minimum=1)
        check_number("solver_tolerance", self.solver_tolerance, 0.0, 1.0, low_open=True, high_open=True)
        check_bool("warm_start", self.warm_start)

    def _fit(self, data: Transitions) -> dict[str, float]:
        coder = self.policy.tile_coder
        theta = self.policy.theta_array
        features = TileFeatures(coder, data.slots, data.actions)
        columns, f, n = features.columns, features.n_features, len(data)
        prior = self._initial_values(features.touched)
        x = theta[features.touched].copy() if self.warm_start else prior.copy()
        self._reset_weights(features.touched, x)

        normal = LinearOperator((f, f), matvec=lambda v: _normal_product(v, columns, self.ridge), dtype=np.float64)
        inverse_diagonal = 1.0 / (features.counts + self.ridge)
        preconditioner = LinearOperator((f, f), matvec=lambda v: inverse_diagonal * v.ravel(), dtype=np.float64)
        next_values = np.empty(n)
        next_actions = np.empty(n, dtype=np.int64)
        fitted = np.empty(n)
        rhs = np.empty(f)
        cg_iterations = 0
        bellman_error = 0.0
        for sweep in range(self.n_iterations):
            # Eq. 3.1: targets from the current Q (policy iteration: Q is fixed during the sweep)
            kernels.greedy_next_values(
                theta,
                data.next_slots,
                data.terminal,
                coder.layout,
                self._q_scratch,
                next_values,
                next_actions,
            )
            targets = data.rewards + self.gamma * next_values
            kernels.features_dot(x, columns, fitted)
            if sweep == 0:
                bellman_error = float(np.mean(np.abs(targets - fitted)))
            self._watch_batch(targets, fitted, f"sweep {sweep + 1} of fit {self.fits + 1}")
            # Alg. 6 line 3: the ridge least-squares projection of the targets onto the tile features
            kernels.features_transpose_dot(targets, columns, rhs)
            rhs += self.ridge * prior
            counter = _Counter()
            x, _ = cg(
                normal,
                rhs,
                x0=x,
                rtol=self.solver_tolerance,
                maxiter=self.solver_iterations,
                M=preconditioner,
                callback=counter,
            )
            cg_iterations += counter.calls
            theta[features.touched] = x
        kernels.features_dot(x, columns, fitted)
        self._td_error_sum += bellman_error * n
        self._td_error_count += n
        return {
            **features_summary(features),
            "bellman_error": bellman_error,
            "fit_residual": float(np.linalg.norm(targets - fitted) / max(np.linalg.norm(targets), 1e-300)),
            "solver_iterations": cg_iterations / self.n_iterations,
        }


def _normal_product(v: np.ndarray, columns: np.ndarray, ridge: float) -> np.ndarray:
    out = np.empty(v.shape[0])
    kernels.ridge_normal_matvec(np.ascontiguousarray(v.ravel()), columns, ridge, out)
    return out


class _Counter:
    """Counts the iterations of an iterative solver (its callback)."""

    def __init__(self):
        self.calls = 0

    def __call__(self, _x) -> None:
        self.calls += 1
