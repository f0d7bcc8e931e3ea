"""The plugin's dataset cards (``lerobot_efm/datasets_cards/*.md``, shipped with the package) as the content of
LeRobot's own Hub card: ``LeRobotDataset.push_to_hub(**card_kwargs(...))`` fills LeRobot's template (description,
paper, citation, tags) instead of leaving "[More Information Needed]"."""

from __future__ import annotations

import re
from pathlib import Path

CARDS_DIR = Path(__file__).resolve().parent / "datasets_cards"
# recordings of lerobot-efm-record: (env type, operator) -> card
RECORDING_CARDS = {
    ("efm_point_reach", "play"): "efm_point_play",
    ("talos_kitchen", "play"): "talos_kitchen_play",
    ("planar_push", "expert"): "planar_push_expert",
    ("planar_push", "full"): "planar_push_full",
    ("planar_push", "partitioned"): "planar_push_partitioned",
}
PAPER = "https://arxiv.org/abs/2505.19717"
CITATION = """@inproceedings{rouxel2025extremum,
  title={Extremum Flow Matching for Offline Goal Conditioned Reinforcement Learning},
  author={Rouxel, Quentin and Donoso, Clemente and Chen, Fei and Ivaldi, Serena and Mouret, Jean-Baptiste},
  booktitle={IEEE-RAS International Conference on Humanoid Robots},
  year={2025}
}"""


def card_kwargs(name: str) -> dict:
    """``tags``, ``license`` and template fields of the card ``name`` (a file of datasets_cards/ without .md)."""
    path = CARDS_DIR / f"{name}.md"
    if not path.is_file():
        valid = sorted(p.stem for p in CARDS_DIR.glob("*.md"))
        raise FileNotFoundError(f"no dataset card {name!r} in {CARDS_DIR}; valid: {valid}")
    text = path.read_text()
    front = re.match(r"---\n(.*?)\n---\n", text, re.DOTALL)
    header = front.group(1) if front else ""
    tags = re.search(r"^tags:\s*\[(.*)\]\s*$", header, re.MULTILINE)
    license_ = re.search(r"^license:\s*(\S+)\s*$", header, re.MULTILINE)
    return {
        "tags": [t.strip() for t in tags.group(1).split(",") if t.strip() and t.strip() != "LeRobot"]
        if tags
        else [],
        "license": license_.group(1) if license_ else "apache-2.0",
        "dataset_description": text[front.end() :].strip() if front else text.strip(),
        "url": "https://pypi.org/project/lerobot_policy_efm/",
        "paper": PAPER,
        "citation_bibtex": CITATION,
    }


def recording_card_kwargs(env_type: str, operator: str) -> dict:
    """The card of a ``lerobot-efm-record`` recording; a generic one for pairs without a card of their own."""
    name = RECORDING_CARDS.get((env_type, operator))
    if name is not None:
        return card_kwargs(name)
    return {
        "tags": ["play-data", "goal-conditioned", "extremum-flow-matching", env_type],
        "license": "apache-2.0",
        "dataset_description": f"Scripted `{operator}` recording of the `{env_type}` environment of lerobot_efm.",
        "paper": PAPER,
        "citation_bibtex": CITATION,
    }
