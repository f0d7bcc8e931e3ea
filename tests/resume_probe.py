"""Runs LeRobot's real lerobot-train main() with two RNG-*order* effects removed, so that a resumed run can be
compared bit for bit with an uninterrupted one (tests/test_resume_exact.py). Both are outside this plugin's
state; everything else (sampler order, weights, EMA, optimiser, scheduler and RNG state saved and loaded) is
LeRobot's own resume path:

* accelerate's DataLoaderShard fetches one batch ahead, and HindsightGoalDataset draws d and g' from the global
  torch RNG in ``__getitem__`` (num_workers=0). The batch after a checkpoint is therefore drawn *before* that
  checkpoint saves the RNG state, and a resumed run draws it again from the saved, later, state. Here each item
  draws from the RNG seeded by its index, and the global RNG is left as it was.
* torch's DataLoader iterator takes a base seed from the global RNG when it is created: at the start of a run,
  hence at another point of the RNG stream in a resumed run. Here that draw leaves the global RNG untouched.
"""

import sys

import lerobot.scripts.lerobot_train as lerobot_train  # loaded first, as the console script does
import torch
import torch.utils.data.dataloader as dataloader

from lerobot_efm.hindsight import HindsightGoalDataset

_iter_init, _getitem = dataloader._BaseDataLoaderIter.__init__, HindsightGoalDataset.__getitem__


def iter_init(self, *args, **kwargs):
    with torch.random.fork_rng(devices=[]):
        _iter_init(self, *args, **kwargs)


def getitem(self, idx):
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(idx))
        return _getitem(self, idx)


dataloader._BaseDataLoaderIter.__init__, HindsightGoalDataset.__getitem__ = iter_init, getitem

if __name__ == "__main__":
    torch.set_num_threads(1)
    sys.argv = ["lerobot-train", *sys.argv[1:]]
    sys.exit(lerobot_train.main())
