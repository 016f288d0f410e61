"""Least-squares policy iteration on the tile features (Lagoudakis and Parr 2003; thesis 3.3.2)."""

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_er.common import kernels
from sb3_er.common.batch import FittedTileQAlgorithm, TileFeatures, Transitions, features_summary, weight_indices
from sb3_er.common.checks import check_integer
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.policies import TileQPolicy

DEFAULT_MAX_FEATURES = 30_000


@inherit_parameters
class LSPI(FittedTileQAlgorithm):
    """LSPI: policy iteration whose evaluation step is LSTD-Q, solved in one step by least squares.

    With Phi (n, f) the binary features phi(s_d, a_d) of the database over the f weights the data touches, and
    Phi'_pi (n, f) the features phi(s'_d, pi(s'_d)) of the greedy policy pi at the next states (a zero row where s'_d
    is terminal), LSTD-Q (Lagoudakis and Parr 2003, Eq. 10-11) solves

        (A + ridge I) w = b + ridge theta_0,   A = Phi^T (Phi - gamma Phi'_pi),   b = Phi^T (r + gamma u),

    sets theta = w on the touched weights and makes pi greedy on the new Q. Weights outside the touched set keep
    their initial values theta_0 (the policy's ``initial_value``, 0 by default; the ridge pulls towards them too), so
    next-state features outside the set are constants: u_d sums their initial weights in phi(s'_d, pi(s'_d)). It
    stops when pi no longer changes on the database's non-terminal next states, or after ``n_iterations``
    evaluations. The first pi is greedy on the current Q (ties go to the lowest action index). The fit runs every
    ``fit_every`` episodes; in between the agent acts epsilon-greedily on Q without learning.

    Solver: a direct sparse LU factorisation (SuperLU via ``scipy.sparse.linalg.splu``) with a symmetric minimum-degree
    ordering and diagonal pivots (A's pattern is nearly symmetric and its diagonal dominant); if that solution's
    residual is poor, it is refactorised with partial pivoting. The ridge term makes singular systems (weights only
    ever active together, as overlapping tilings produce) solvable. LU fill grows faster than f (thesis 3.5.4: LSPI is
    O(nE f^3)), and with the tilings too (a row of A couples a feature with those of the other N - 1 tilings at the
    same samples), so a system of more than ``max_features`` touched features is refused. Measured per policy
    evaluation on pendulum data: 4 tilings, f = 12,600: 0.7 s; 8 tilings, f = 25,000: 5 s; 16 tilings of
    (0.33 rad, 3.3 rad/s), f = 10,300: 5 s, and minutes once the data grew; 16 tilings of the printed
    (0.33, 0.33) touch 380,000 features.

    :param fit_every: episodes between fits (default 5).
    :param n_iterations: maximum policy-evaluation steps per fit (>= 1; default 10).
    :param ridge: lambda of the ridge term (> 0, default 1, in units of squared feature activations; on MountainCar
        0.01 left the policy oscillating between fits where 1 converged in 3-5 evaluations).
    :param max_features: the largest system (touched features) to factorise (default 30,000).
    :param buffer_size: transitions kept; the oldest whole trajectories are evicted beyond it.
    :param learning_rate: not used: every evaluation solves LSTD-Q's system exactly.
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        fit_every: int = 5,
        n_iterations: int = 10,
        ridge: float = 1.0,
        max_features: int = DEFAULT_MAX_FEATURES,
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
        self.max_features = max_features
        self.policy_iterations = 0
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
        check_integer("max_features", self.max_features, minimum=1)

    def _too_large(self, n_features: int, n_transitions: int) -> ValueError:
        return ValueError(
            f"LSPI's least-squares system has {n_features} unknowns (the tile features that the {n_transitions} "
            f"stored transitions touch), more than max_features={self.max_features}: its sparse LU factorisation would "
            "take too long or too much memory (the cost grows faster than the number of features). Shrink it with "
            "fewer tilings (policy_kwargs n_tilings), wider tiles (policy_kwargs tile_widths), or a smaller "
            "buffer_size; or raise max_features if you have the memory and time."
        )

    def _fit(self, data: Transitions) -> dict[str, float]:
        coder = self.policy.tile_coder
        theta = self.policy.theta_array
        n = len(data)
        features = TileFeatures(coder, data.slots, data.actions)
        f = features.n_features
        if f > self.max_features:
            raise self._too_large(f, n)
        phi = features.matrix()
        phi_t = phi.T.tocsr()
        prior = self._initial_values(features.touched)
        regulariser = self.ridge * sp.identity(f, format="csc")
        next_values = np.empty(n)
        policy = np.empty(n, dtype=np.int64)
        new_policy = np.empty(n, dtype=np.int64)
        kernels.greedy_next_values(
            theta,
            data.next_slots,
            data.terminal,
            coder.layout,
            self._q_scratch,
            next_values,
            policy,
        )
        w = theta[features.touched].copy()
        self._reset_weights(features.touched, w)
        bellman_error = float(np.mean(np.abs(data.rewards + self.gamma * next_values - phi @ w)))
        changed = n
        iterations = 0
        for _ in range(self.n_iterations):
            # LSTD-Q for the fixed greedy policy pi (policy evaluation)
            next_columns = features.columns_of(data.next_slots, policy)
            phi_next = features.matrix(next_columns)
            a = (phi_t @ (phi - self.gamma * phi_next)).tocsc() + regulariser
            b = phi_t @ (data.rewards + self.gamma * self._outside_values(data.next_slots, policy, next_columns))
            w = self._solve(a, b + self.ridge * prior, n)
            theta[features.touched] = w
            iterations += 1
            # policy improvement: greedy at every next state of the database
            kernels.greedy_next_values(
                theta,
                data.next_slots,
                data.terminal,
                coder.layout,
                self._q_scratch,
                next_values,
                new_policy,
            )
            self._watch_batch(
                data.rewards + self.gamma * next_values,
                phi @ w,
                f"policy iteration {iterations} of fit {self.fits + 1}",
            )
            changed = int(np.count_nonzero(new_policy != policy))
            policy, new_policy = new_policy, policy
            if changed == 0:
                break
        self.policy_iterations += iterations
        self._td_error_sum += bellman_error * n
        self._td_error_count += n
        return {
            **features_summary(features),
            "bellman_error": bellman_error,
            "policy_iterations": iterations,
            "policy_changes": changed,
        }

    def _outside_values(self, next_slots: np.ndarray, policy: np.ndarray, next_columns: np.ndarray) -> np.ndarray:
        """u (n,): per transition, the sum of the weights of phi(s', pi(s')) outside the touched set, which hold their
        initial values during the fit (0 when the initial value is 0)."""
        low, span, _ = self.policy.initial_arguments
        outside = (next_columns < 0) & (policy >= 0)[:, None]
        if (low == 0.0 and span == 0.0) or not outside.any():
            return np.zeros(next_slots.shape[0])
        indices = weight_indices(self.policy.tile_coder, next_slots, np.maximum(policy, 0))
        return np.where(outside, self.policy.theta_array[indices], 0.0).sum(axis=1)

    def _solve(self, a: sp.csc_matrix, b: np.ndarray, n_transitions: int) -> np.ndarray:
        """w = a^-1 b by sparse LU: diagonal pivots on a symmetric ordering first, partial pivoting if that is poor."""
        try:
            try:
                lu = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
                w = lu.solve(b)
                if np.all(np.isfinite(w)) and np.linalg.norm(a @ w - b) <= 1e-8 * max(np.linalg.norm(b), 1e-300):
                    return w
            except RuntimeError:  # a zero diagonal pivot: retry with partial pivoting
                pass
            return splu(a).solve(b)
        except MemoryError:
            raise self._too_large(a.shape[0], n_transitions) from None
        except RuntimeError as error:
            raise ValueError(
                f"LSPI's least-squares system is singular ({error}): raise ridge (now {self.ridge})"
            ) from None

    def _record_train_metrics(self) -> None:
        super()._record_train_metrics()
        self.logger.record("train/policy_iterations_total", self.policy_iterations)
