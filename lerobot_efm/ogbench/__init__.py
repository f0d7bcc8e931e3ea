"""OGBench adapter: local pointmaze data generation, npz -> LeRobot conversion and the ``ogbench`` env type.

Importing this package registers the ``ogbench`` env type with LeRobot and its gym id; ``ogbench`` itself
(MuJoCo, dm_control) is imported only when an env is built or data is generated.
"""

from .env import GYM_ID as OGBENCH_GYM_ID
from .env import OGBenchEnv, OGBenchEnvConfig

__all__ = ["OGBENCH_GYM_ID", "OGBenchEnv", "OGBenchEnvConfig"]
