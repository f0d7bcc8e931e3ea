"""Command-line scripts of lerobot_efm (rerun rollouts and dataset logging)."""
