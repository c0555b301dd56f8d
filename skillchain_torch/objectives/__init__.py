"""Update rules ("objectives" in TorchRL terms); linear ones apply closed-form TD steps."""

from skillchain_torch.objectives.sarsa import SarsaUpdate, discount, smdp_td_error

__all__ = ["SarsaUpdate", "discount", "smdp_td_error"]
