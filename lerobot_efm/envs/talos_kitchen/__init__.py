"""MuJoCo Talos kitchen: run-time scene (:mod:`.scene`) and Cartesian left-hand control (:mod:`.control`).

Importing this package does not import MuJoCo; import the submodules (after setting ``MUJOCO_GL``).
"""
