"""The Gymnasium ids of the shipped Pinball maps, registered without importing torch.

``import skillchain_torch`` calls :func:`register_gym_envs`, so ``gym.make`` finds the ids
after it: each id names its env by an entry-point string, and Gymnasium imports the Pinball
package (torch and all) only when an env is made. The ids come from the map files' names.

Example:
    >>> import gymnasium as gym
    >>> import skillchain_torch  # registers the ids
    >>> "skillchain_torch/Pinball-SimpleSingle-v0" in gym.registry
    True
    >>> GYM_IDS["skillchain_torch/Pinball-HardTwoStarts-v0"]
    'pinball_hard_two_starts'
"""

from __future__ import annotations

from importlib import resources

__all__ = ["GYM_IDS", "ENTRY_POINT", "register_gym_envs"]

ENTRY_POINT = "skillchain_torch.envs.pinball.gym_adapter:GymPinballEnv"


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.removeprefix("pinball_").split("_"))


def _map_names() -> tuple[str, ...]:
    # The same files envs.pinball.maps.MAP_NAMES lists, read here without importing it.
    try:
        entries = list((resources.files(__package__) / "pinball" / "maps").iterdir())
    except (ModuleNotFoundError, FileNotFoundError, NotADirectoryError):
        return ()
    return tuple(sorted(e.name[:-4] for e in entries if e.name.endswith(".cfg")))


GYM_IDS = {f"skillchain_torch/Pinball-{_camel(name)}-v0": name for name in _map_names()}


def register_gym_envs() -> None:
    """Register one Gymnasium id per shipped map (idempotent)."""
    import gymnasium as gym

    for env_id, name in GYM_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=ENTRY_POINT, kwargs={"map": name})
