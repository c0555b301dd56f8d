"""Re-run a committed run's exact configuration into a new folder (its ``config.json``, with
optional ``field=value`` overrides), or continue that folder from its last checkpoint.

    python results/neural/rerun.py FROM_DIR TO_DIR [field=value ...]

The eleventh session re-ran every neural result this way after per-agent replay
(``skillchain_torch/objectives/agent_storage.py``) changed what a neural agent samples.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.loop.population import PopulationTrainer
from skillchain_torch.trainers.outputs.run_outputs import train_and_write


def main(argv: list[str]) -> int:
    source, out, *overrides = argv
    out = Path(out)
    if (out / "returns.npy").is_file():
        print(f"{out}: done")
        return 0
    if (out / "checkpoints").is_dir() and any((out / "checkpoints").iterdir()):
        return subprocess.call([sys.executable, "-m", "skillchain_torch.trainers.config.cli",
                                "train", "--resume", str(out), "--quiet", "--threads", "1"])
    fields = json.loads((Path(source) / "config.json").read_text())
    for item in overrides:
        key, value = item.split("=", 1)
        fields[key] = json.loads(value)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(fields, indent=2) + "\n")
    config = TrainConfig.load_json(out / "config.json")
    trainer = PopulationTrainer(config, out_dir=out, num_threads=1)
    return train_and_write(trainer, out, quiet=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
