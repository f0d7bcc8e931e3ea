"""Runs LeRobot's real lerobot-train main() under `accelerate launch`, recording per rank which dataset
indices each step trained on and a fingerprint of the weights after each update (tests/test_multiprocess.py)."""

import json
import os
import sys

import lerobot.scripts.lerobot_train as lerobot_train  # loaded first, as the console script does
import torch

from lerobot_efm.modeling_efm import EFMPolicy

record = {"indices": [], "fingerprints": []}
rank = int(os.environ.get("RANK", "0"))
out_dir = os.environ["EFM_PROBE_DIR"]
forward, update = EFMPolicy.forward, EFMPolicy.update


def probed_forward(self, batch):
    record["indices"].append(batch["index"].tolist())
    return forward(self, batch)


def probed_update(self):
    update(self)
    record["fingerprints"].append([float(p.double().sum()) for p in self.model.parameters()][:8])
    with open(os.path.join(out_dir, f"rank{rank}.json"), "w") as f:
        json.dump(record, f)


EFMPolicy.forward, EFMPolicy.update = probed_forward, probed_update

if __name__ == "__main__":
    torch.set_num_threads(1)
    sys.argv = ["lerobot-train", *sys.argv[1:]]
    lerobot_train.main()
