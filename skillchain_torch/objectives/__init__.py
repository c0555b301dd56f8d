"""Update rules ("objectives" in TorchRL terms): closed-form TD steps for the linear heads
(:class:`SarsaUpdate`, :class:`IntraOptionQLearning`) and the same rules as TorchRL loss modules
(:class:`SMDPSarsaLoss`, :class:`IntraOptionQLoss`) for heads trained by an optimizer, and
:class:`ReplayTD` and :class:`OptionReplay`, replay and target networks for neural heads, each
agent's own memory in an :class:`AgentReplayStorage`."""

from skillchain_torch.objectives.agent_storage import AgentReplayStorage
from skillchain_torch.objectives.intra_option_loss import IntraOptionQLoss
from skillchain_torch.objectives.option_replay import OptionReplay
from skillchain_torch.objectives.q_learning import (
    IntraOptionQLearning,
    option_td_target,
    option_update_mask,
)
from skillchain_torch.objectives.replay import ReplayTD
from skillchain_torch.objectives.sarsa import SarsaUpdate, discount, smdp_td_error
from skillchain_torch.objectives.smdp_sarsa_loss import SMDPSarsaLoss

__all__ = [
    "AgentReplayStorage",
    "IntraOptionQLearning",
    "IntraOptionQLoss",
    "OptionReplay",
    "ReplayTD",
    "SMDPSarsaLoss",
    "SarsaUpdate",
    "discount",
    "option_td_target",
    "option_update_mask",
    "smdp_td_error",
]
