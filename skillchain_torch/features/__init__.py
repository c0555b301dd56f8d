"""State features for linear function approximation."""

from skillchain_torch.features.fourier import FourierBasis
from skillchain_torch.features.polynomial import PolynomialFeatures

__all__ = ["FourierBasis", "PolynomialFeatures"]
