"""Recorder options the paper runner pins per planar-push dataset, in one place for the runner and the plots.

The committed partitioned cells were run on play recorded before wall slides, open-space stops and balanced
corners became the recorder's defaults (measured on full play only), so the runner passes these options when it
records that dataset, and the plots treat a recording made with only these as the dataset's standard one
(anything beyond them is another recording: another setting, not more seeds). Plain data, no imports: the
plotting scripts load it without torch or lerobot.
"""

PLANAR_PINS: dict[str, tuple[str, ...]] = {
    "partitioned": ("wall_slides=0", "open_stops=0", "balanced_corners=false"),
}

# every pinned option (``NAME=VALUE``, without ``--operator.``): not a mark of a non-standard recording
STANDARD_OPTIONS = frozenset(option for options in PLANAR_PINS.values() for option in options)
