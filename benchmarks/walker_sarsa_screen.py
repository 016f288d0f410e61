"""Screen on Sarsa(lambda) what thesis 4.2.2 leaves open, from starts that always make a passive footstep.

Run from the repository root (10 seeds, 5000 s of learning time, one `sb3-er reproduce` folder per candidate; resumes):

    nice -n 10 .venv/bin/python benchmarks/walker_sarsa_screen.py [--only NAME ...] [--summary-only] [--out DIR]

The printed reading: -1 per control step, +50 per unit of footstep length (the legs are one unit long), -50 and the end
of the episode when the hip touches the ground, the state of Eq. 4.2 observed. Candidates vary the footstep reward's
unit and cap ("schuitema": GRL's min(50 * 4 sin phi_st, 30) in place of the step's -1), the fall test ("angles": GRL's
|phi_st| > pi/8 or |phi_h - 2 phi_st| > pi/4) and the observation ("grl": phi_h - 2 phi_st and its rate), from the
start on the impact manifold ("impact") and from GRL's start redrawn until a zero-action walk makes a footstep
("grl_footstep"). Table 4.2's tile widths and 15 hip accelerations throughout. The summary ranks them by the readings
rule against the thesis's Table 6.2 Sarsa(lambda) row.
"""

from pathlib import Path

from sb3_er.experiments.screen import Candidate, screen_command

#: The screen's folder (--out): a sub-folder per candidate, its summary.md and summary.csv.
OUT = Path(__file__).resolve().parents[1] / "results" / "measured" / "walker_sarsa_screen"
LITERAL = {"reward": "literal"}
SCHUITEMA = {"reward": "schuitema"}
HIP, ANGLES = {"fall": "hip"}, {"fall": "angles"}
THESIS, GRL = {"observation": "thesis"}, {"observation": "grl"}
PRINTED_REWARD = "reward: -1 per control step, +50 per meter of footstep, -50 at a fall"
PRINTED_FALL = "fall: the hip mass touches the ground"
PRINTED_OBSERVATION = "observation: the state of Eq. 4.2"


def _printed(kwargs) -> frozenset:
    """The printed values a reading keeps (the footstep reward's cap is what the text leaves open)."""
    labels = set()
    if kwargs.get("reward") == "literal" and kwargs.get("step_reward", 50.0) == 50.0:
        labels.add(PRINTED_REWARD)
    if kwargs.get("fall") == "hip":
        labels.add(PRINTED_FALL)
    if kwargs.get("observation") == "thesis":
        labels.add(PRINTED_OBSERVATION)
    return frozenset(labels)


def _candidates():
    candidates = []
    for start in ("impact", "grl_footstep"):
        for reward_name, reward in (("literal", LITERAL), ("schuitema", SCHUITEMA)):
            for fall_name, fall in (("hip", HIP), ("angles", ANGLES)):
                for observation_name, observation in (("thesis", THESIS), ("grl", GRL)):
                    if start == "grl_footstep" and (fall_name, observation_name) not in (
                        ("hip", "thesis"),
                        ("angles", "grl"),
                    ):
                        continue
                    name = f"{start}_{reward_name}_{fall_name}_{observation_name}"
                    reading = f"start {start}, {reward_name} reward, {fall_name} fall, {observation_name} observation"
                    if (start, reward_name, fall_name, observation_name) == ("impact", "literal", "hip", "thesis"):
                        reading = "the printed reading: " + reading
                    kwargs = {"start": start, **reward, **fall, **observation}
                    candidates.append(Candidate(name, kwargs, reading, _printed(kwargs)))
    printed = {"start": "impact", **LITERAL, **HIP, **THESIS}
    candidates += [
        Candidate(
            "impact_literal_cap30_hip_thesis",
            {**printed, "step_reward_cap": 30.0},
            "start impact, literal reward capped at 30, hip fall, thesis observation",
        ),
        Candidate(
            "impact_literal100_cap30_hip_thesis",
            {**printed, "step_reward": 100.0, "step_reward_cap": 30.0},
            "start impact, -1 per step and -50 at a fall as printed, +100 per unit of step length (legs of 2 m) "
            "capped at 30, hip fall, thesis observation",
        ),
        Candidate(
            "impact_schuitema_uncapped_angles_grl",
            {"start": "impact", **SCHUITEMA, **ANGLES, **GRL, "step_reward_cap": 1e9},
            "start impact, schuitema reward without its cap (1e9), angles fall, grl observation",
        ),
        Candidate(
            "impact_schuitema_uncapped_hip_thesis",
            {"start": "impact", **SCHUITEMA, **HIP, **THESIS, "step_reward_cap": 1e9},
            "start impact, schuitema reward without its cap (1e9), hip fall, thesis observation",
        ),
        Candidate(
            "impact_v0.2_schuitema_hip_thesis",
            {"start": "impact", "initial_state_variation": 0.2, **SCHUITEMA, **HIP, **THESIS},
            "start impact with the stance angle varied by 20 % (not 10 %), schuitema reward, hip fall, thesis "
            "observation",
        ),
    ]
    return [
        candidate
        if candidate.printed
        else Candidate(candidate.name, candidate.env_kwargs, candidate.description, _printed(candidate.env_kwargs))
        for candidate in candidates
    ]


CANDIDATES = _candidates()

if __name__ == "__main__":
    screen_command(
        "walker",
        CANDIDATES,
        OUT,
        "Simplest walker: Sarsa(λ) screen (thesis Table 6.2)",
        notes=__doc__.split("\n\n", 1)[0] + " 5000 s of learning time per run; every 100 s, 10 greedy 100 s runs.",
    )
