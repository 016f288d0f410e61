"""The thesis's own results (Tables 6.1-6.3), quoted so that our tables can print them beside ours.

Values are (average, difference with Sarsa(lambda) in percent) exactly as printed; a leading ">" in the thesis
(a rise time beyond the run, falls counted up to the end of the run) is kept as text, "NA" as None.
"""

from __future__ import annotations

LITERAL_LABELS = {
    "sarsa_lambda": "Sarsa(λ)",
    "er": "vanilla-ER",
    "er_sigma": "ER-σ",
    "residual_er": "residual ER",
    "residual_er_sigma": "residual ER-σ",
}
"""The thesis's five algorithms by rl-zoo name, with the labels of its tables."""

#: The stable learner's rows of the tables: each ER class with ``preset="stable"`` (the projection of the weights
#: onto the possible returns, docs/stable_replay.md) under the table's own replay protocol, judged against Sarsa(λ)
#: on the thesis's claims for the same algorithm.
STABLE_ROWS = {f"{algo}_stable": algo for algo in ("er", "er_sigma", "residual_er", "residual_er_sigma")}

ALGORITHM_LABELS = {**LITERAL_LABELS, **{row: f"{LITERAL_LABELS[algo]} (stable)" for row, algo in STABLE_ROWS.items()}}
"""Every row of the tables by name: the thesis's five algorithms, then the stable learner's rows."""


def row_algorithm(row: str) -> tuple[str, dict[str, str]]:
    """(the rl-zoo name of the algorithm, its constructor arguments) of a table's row: "er_sigma_stable" ->
    ("er_sigma", {"preset": "stable"}); a literal row is its algorithm with no argument.

    :param row: the row's name, a key of :data:`ALGORITHM_LABELS`.
    """
    if row in STABLE_ROWS:
        return STABLE_ROWS[row], {"preset": "stable"}
    return row, {}


ThesisEntry = tuple[float | str | None, str]

# Table 6.1, inverted pendulum: rise time in episodes, end performance as accumulated reward.
PENDULUM: dict[str, dict[str, ThesisEntry]] = {
    "sarsa_lambda": {"rise_time": (22, "-"), "end_performance": (-1.673e4, "-")},
    "er": {"rise_time": (11, "-50 %"), "end_performance": (-4065, "+76 %")},
    "er_sigma": {"rise_time": (9, "-60 %"), "end_performance": (-3692, "+78 %")},
    "residual_er": {"rise_time": (10, "-55 %"), "end_performance": (-3913, "+77 %")},
    "residual_er_sigma": {"rise_time": (11, "-50 %"), "end_performance": (-6200, "+63 %")},
}

# Table 6.2, simplest walker: rise time in seconds of learning time, end performance in meters per 100 s.
WALKER: dict[str, dict[str, ThesisEntry]] = {
    "sarsa_lambda": {"rise_time": (1500, "-"), "end_performance": (11.7, "-"), "falls": (74, "-")},
    "er": {"rise_time": (3400, "+126 %"), "end_performance": (11.7, "0 %"), "falls": (150, "+51 %")},
    "er_sigma": {"rise_time": (500, "-67 %"), "end_performance": (11.5, "-2 %"), "falls": (44, "-41 %")},
    "residual_er": {"rise_time": (3400, "+126 %"), "end_performance": (11.7, "0 %"), "falls": (140, "+48 %")},
    "residual_er_sigma": {"rise_time": (500, "-67 %"), "end_performance": (12.0, "+3 %"), "falls": (45, "-39 %")},
}

# Table 6.3, LEO: rise time in minutes of learning time, end performance in meters per 25 s.
LEO: dict[str, dict[str, ThesisEntry]] = {
    "sarsa_lambda": {"rise_time": (160, "-"), "end_performance": (6.5, "-"), "falls": (3792, "-")},
    "er": {"rise_time": (">200", ">+25 %"), "end_performance": (None, "-"), "falls": (">6170", ">+93 %")},
    "er_sigma": {"rise_time": (133, "-17 %"), "end_performance": (5.2, "-20 %"), "falls": (2416, "-36 %")},
    "residual_er": {"rise_time": (">200", ">+25 %"), "end_performance": (None, "-"), "falls": (">5862", ">+93 %")},
    "residual_er_sigma": {"rise_time": (87, "-46 %"), "end_performance": (5.5, "-15 %"), "falls": (1550, "-59 %")},
}
