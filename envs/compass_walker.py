"""GRL's compass-walker walk task: the simplest walker as the Delft lab's later framework sets it up, for cross-checks.

GRL (github wcaarls/grl) descends from the code the thesis ran (Schuitema 2012). Its walk task with Sarsa(lambda) is a
peer to compare against: :class:`CompassWalkerEnv` rebuilds that task on our simulation
(:mod:`sb3_er_envs.simplest_walker`, same equations of motion, impact map and root-found heel strikes). Every setting
below comes from GRL's source at ``base/src/environments/compass_walker/`` (``compass_walker.cpp`` for the model,
walk task, start, observation, reward and falls; ``SWModel.cpp`` / ``SWModel.h`` for the integrator) and
``cfg/compass_walker/sarsa_walk.yaml`` (the experiment); the file is named with each fact.

* Dynamics (``compass_walker.h`` defaults, ``sarsa_walk.yaml``): control step 0.2, 20 RK4 substeps, slope 0.004; the
  hip action is an acceleration added to the hip equation (``SWModel.cpp``). At a heel strike GRL continues the
  integration from the post-impact state for the rest of the substep, as we do. (GRL finds the heel strike as the
  swing foot's height crossing zero with the swing leg in front; we find it as ``phi_h - 2 phi_st`` rising through 0
  with ``phi_st < 0``: the same event.)
* Actions (``sarsa_walk.yaml``, uniform discretizer with 3 steps over the task's action range +-1.2 in
  ``compass_walker.cpp``): hip accelerations ``{-1.2, 0, 1.2}``. GRL tile-codes the action with width 1.2, exactly
  the spacing of the levels, so no two actions ever share a tile: the same as keeping actions apart, our default.
* Observation (``compass_walker.cpp``, ``observe``; ``observe: [1, 1, 1, 1, 1, 0, 0]`` in ``sarsa_walk.yaml``):
  ``[phi_st, phi_h - 2 phi_st, phi_st', phi_h' - 2 phi_st', changed]``, where ``changed`` is 1 when a heel strike
  happened during the last control step (0 at the start). Tile widths (``sarsa_walk.yaml``, ``resolution``):
  0.0838, 0.1047, 0.1111, 0.2222 and 10 for the flag, 16 tilings, nothing wrapped. With GRL's tiling offsets (tiling
  ``j`` shifted by ``j (1 + 2 d) / 16`` tiles in dimension ``d``, ours too) a width of 10 separates the flag's 0 from
  its 1 in one tiling of 16.
* Reward (``compass_walker.cpp``, ``evaluate``): -1 per control step; a step in which the stance leg changed pays
  ``min(50 * 4 sin(phi_st), 30)`` instead, ``phi_st`` read from the state at the end of the control step; a fall pays
  ``negative_reward`` = -100 (``sarsa_walk.yaml``) instead of either.
* Fall (``compass_walker.cpp``, ``observe`` and ``evaluate``): ``|phi_st| > pi/8`` or ``|phi_h - 2 phi_st| > pi/4``
  in the state after a control step; absorbing (``terminated``).
* Start (``compass_walker.cpp``, ``start``): each of Garcia's four post-impact values (0.1534, 0.3068, -0.1561,
  -0.0073) times its own ``U[1 - v, 1 + v]``, ``v = initial_state_variation`` = 0.2 (``sarsa_walk.yaml``), drawn
  again while ``phi_st'^2 / 2 + cos(phi_st) cos(mu) < cos(mu)``: the stance leg's kinetic energy must lift the hip
  to its height at ``phi_st = 0`` (measured along the slope normal). That is a little stricter than passing the top
  at ``phi_st = mu``, so every start passes mid-stance. The legs need not start symmetric. Test episodes start at
  Garcia's values exactly (variation 0).
* Episodes (``compass_walker.cpp``, ``start`` and ``observe``; ``timeout: 100`` in ``sarsa_walk.yaml``): a learning
  episode ends when its time exceeds 100, a test episode when it exceeds 200; with the time summed in steps of 0.2
  that is after 500 and 1001 control steps. The time limit is ``truncated`` (GRL bootstraps there too).
* Learning (``sarsa_walk.yaml``, ``representation/parameterized/linear`` with ``init_min: [0]``, ``init_max: [1]``):
  Sarsa(lambda) with alpha 0.4 on Q (GRL averages its 16 active weights), gamma 0.99, lambda 0.92, epsilon 0.05,
  replacing traces, each weight drawn from U[0, 1] so that Q starts in [0, 1]; a greedy test episode after every 10
  learning episodes. These belong to the learner, not the env.

The 1001-step greedy test env of GRL's protocol::

    gymnasium.make("sb3_er/CompassWalker-v0", episode_steps=TEST_EPISODE_STEPS, initial_state_variation=0.0)

``info``, ``env.state``, ``reset(options={"state": s})`` and rendering are those of
:class:`~sb3_er_envs.simplest_walker.SimplestWalkerEnv`.
"""

from __future__ import annotations

from sb3_er_envs.simplest_walker import GRL_TILE_WIDTHS, SimplestWalkerEnv

LEARNING_EPISODE_STEPS = 500
"""GRL's learning episodes: time limit 100 at 0.2 per control step."""
TEST_EPISODE_STEPS = 1001
"""GRL's greedy test episodes: time limit 2 x 100, which the summed time first exceeds after 1001 control steps."""


class CompassWalkerEnv(SimplestWalkerEnv):
    """GRL's compass-walker walk task (module docstring): 3 hip accelerations, GRL's observation, reward and falls.

    Parameters
    ----------
    episode_steps:
        Control steps after which the episode is truncated: 500 (GRL's learning episodes, the default) or
        :data:`TEST_EPISODE_STEPS` = 1001 for GRL's test episodes.
    initial_state_variation:
        ``v`` of the start distribution (0.2, GRL's); 0 starts at Garcia's fixed point, as GRL's test episodes do.
    render_mode:
        ``None`` or ``"rgb_array"``.
    """

    _stance_change_flag = True
    stance_change_tile_width = 10.0

    def __init__(
        self,
        episode_steps: int = LEARNING_EPISODE_STEPS,
        initial_state_variation: float = 0.2,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(episode_steps, bool) or int(episode_steps) != episode_steps or episode_steps < 1:
            raise ValueError(f"episode_steps must be a positive integer, got {episode_steps!r}")
        super().__init__(
            slope=0.004,
            max_hip_acceleration=1.2,
            n_actions=3,
            dt=0.2,
            substeps=20,
            episode_seconds=0.2 * int(episode_steps),
            reward="schuitema",
            fall="angles",
            observation="grl",
            start="grl",
            tile_widths=GRL_TILE_WIDTHS,
            step_reward=50.0,
            step_reward_cap=30.0,
            fall_reward=-100.0,
            time_reward=-1.0,
            initial_state_variation=initial_state_variation,
            render_mode=render_mode,
        )
        self.max_episode_steps = int(episode_steps)
