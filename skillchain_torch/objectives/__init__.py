"""Update rules ("objectives" in TorchRL terms); linear ones apply closed-form TD steps."""

from skillchain_torch.objectives.q_learning import IntraOptionQLearning, option_td_target
from skillchain_torch.objectives.sarsa import SarsaUpdate, discount, smdp_td_error

__all__ = [
    "IntraOptionQLearning",
    "SarsaUpdate",
    "discount",
    "option_td_target",
    "smdp_td_error",
]
