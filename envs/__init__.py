"""Environments for skillchain_torch (installed as ``skillchain_torch.envs``)."""
