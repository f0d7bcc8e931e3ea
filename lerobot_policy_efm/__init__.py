import lerobot_efm  # noqa: F401  (registers the efm_* policies with LeRobot)
