"""Config values the committed reports ran with before a config file changed them, for the plots' labels.

A cell's setting label is its config's name plus what set the run apart. Reports made before the runner
recorded each cell's resolved ``policy_config`` ran the config file as it was then, overridden only by their
``--train-arg`` flags. When a config's value changes later, a new cell that runs the new value without a flag must
not be labelled like the old cells: the plots compare its resolved value with the value listed here and name the
departure (``optimizer_lr=3e-4``), so it groups with the old cells that set that value by flag. Plain data, no
imports: the plotting scripts load it without torch or lerobot.
"""

LABEL_BASELINES: dict[str, dict[str, float | str]] = {
    # 1e-4 (the paper's, tuned for 200k steps) until 2026-12-05; since then the 12k-step CPU runs' measured best
    # (README "Results"): 1e-3 for planar push, 3e-4 for pointmaze
    "planar_push_efm_cpu": {"optimizer_lr": 1e-4},
    # the raw state until 2026-12-05, then Fourier features (every pointmaze cell measured gained with them)
    "ogbench_pointmaze_efm_cpu": {"optimizer_lr": 1e-4, "state_encoder": "identity"},
}
