"""Screen a reading that has no flag: the default preset with some of its fields replaced, or a
frozen option's policy copied again when its initiation set is learned (tenth session).

    python results/option-learning/screen_override.py NAME '{"option_epsilon": 0.0}'
    python results/option-learning/screen_override.py NAME \
        '{"capacity": 2000, "store_failures": true, "constrain_nearest": true}'
    python results/option-learning/screen_override.py NAME '{}' --refresh-at-learned

Runs ``skillchain train --agent skill-chaining`` on the screening block (seeds 0-19, 20 x 250,
checkpoints every 50 episodes) into ``screen/NAME`` in this process, one worker: the override is
made in this interpreter, and Ray's workers would not see it. A folder with a checkpoint and no
``returns.npy`` is resumed (with the same override: pass the same arguments).

``--refresh-at-learned``: when an option's initiation set converges (``LEARNED``, section 5.1's
"learned well enough"), its frozen policy is copied again from the top level's primitive values,
which have had more episodes to learn than at joining (the copy the default takes after a
gestation of 2 episodes). Screening only; not a flag of the library.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def refresh_at_learned() -> None:
    """Wrap ``EpisodeRules.end_episodes``: options that became ``LEARNED`` in this call get the
    top level's primitive values again (the projection the join used)."""
    from skillchain_torch.discovery import episode_rules
    from skillchain_torch.options import OptionStatus

    end_episodes = episode_rules.EpisodeRules.end_episodes

    def refreshed(self, rows, q_head):
        before = self.bank.status == OptionStatus.LEARNED
        end_episodes(self, rows, q_head)
        new = (self.bank.status == OptionStatus.LEARNED) & ~before
        if bool(new.any()) and self.policy_start != "zero":
            if self._projection is None:
                self._projection = episode_rules.cached_projection(self.top_basis,
                                                                   self.bank.q_head.basis)
            episode_rules.initialise_option_policies(self.bank.q_head, q_head, new,
                                                     self._projection, self.bank.num_actions)

    episode_rules.EpisodeRules.end_episodes = refreshed


def main(argv: list[str]) -> int:
    name, override, *rest = argv
    refresh = "--refresh-at-learned" in rest
    if refresh:
        rest.remove("--refresh-at-learned")
        refresh_at_learned()
    from skillchain_torch import presets

    presets.PRESETS["default"] = presets.DEFAULT.replace(**json.loads(override))
    from skillchain_torch.trainers.config.cli import main as skillchain

    out = HERE / "screen" / name
    if (out / "returns.npy").exists():
        print(f"{name}: done")
        return 0
    if (out / "checkpoints").is_dir():
        code = skillchain(["train", "--resume", str(out), "--workers", "1", "--quiet"])
    else:
        code = skillchain(["train", "--agent", "skill-chaining", "--map", "pinball_simple_single",
                           "--runs", "20", "--episodes", "250", "--seed", "0", "--workers", "1",
                           "--checkpoint-every", "50", "--quiet", "--out", str(out), *rest])
    # config.json cannot hold the override: say it beside it
    (out / "override.json").write_text(json.dumps(
        {"preset_fields": json.loads(override), "refresh_at_learned": refresh}, indent=2) + "\n")
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
