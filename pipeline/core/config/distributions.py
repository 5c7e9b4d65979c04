"""Parameter distributions for sampled vehicle attributes.

A distribution is written in YAML as a mapping with a ``dist`` key, e.g.
``{dist: truncnormal, mean: 1.2, std: 0.3, low: 0.5, high: 2.5}``. Sampling takes an explicit
``numpy.random.Generator`` so every draw derives from the run's seed.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from pipeline.core.config.base import ConfigModel


def _stats():
    """scipy.stats, imported on first use: it costs a noticeable start-up in every CLI call and render worker,
    and only the simulate stage samples from these distributions."""
    from scipy import stats

    return stats


class _Dist(ConfigModel):
    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def cdf(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """The distribution's CDF (used by the statistical tests and docs)."""
        raise NotImplementedError


class Constant(_Dist):
    """Always ``value``."""

    dist: Literal["constant"] = "constant"
    value: float

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.full(n, self.value, dtype=np.float64)

    def cdf(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) >= self.value).astype(np.float64)


class Uniform(_Dist):
    """Uniform on [low, high]."""

    dist: Literal["uniform"] = "uniform"
    low: float
    high: float

    @model_validator(mode="after")
    def _check(self) -> Uniform:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(self.low, self.high, size=n)

    def cdf(self, x: np.ndarray) -> np.ndarray:
        return _stats().uniform(self.low, self.high - self.low).cdf(x)


class TruncNormal(_Dist):
    """Normal(mean, std) truncated to [low, high] (by inverse CDF, so no rejection loop)."""

    dist: Literal["truncnormal"] = "truncnormal"
    mean: float
    std: float = Field(gt=0)
    low: float
    high: float

    @model_validator(mode="after")
    def _check(self) -> TruncNormal:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self

    def _frozen(self):
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return _stats().truncnorm(a, b, loc=self.mean, scale=self.std)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return self._frozen().ppf(rng.uniform(size=n))

    def cdf(self, x: np.ndarray) -> np.ndarray:
        return self._frozen().cdf(x)


class LogNormal(_Dist):
    """exp(Normal(mu, sigma)), optionally truncated to [low, high]; ``median`` = exp(mu)."""

    dist: Literal["lognormal"] = "lognormal"
    median: float = Field(gt=0)
    sigma: float = Field(gt=0)
    low: float = 0.0
    high: float | None = Field(None, description="upper truncation; None = not truncated above")

    @model_validator(mode="after")
    def _check(self) -> LogNormal:
        if not 0 <= self.low < (np.inf if self.high is None else self.high):
            raise ValueError(f"need 0 <= low < high, got low={self.low}, high={self.high}")
        return self

    def _base(self):
        return _stats().lognorm(s=self.sigma, scale=self.median)

    def _cdf_bounds(self) -> tuple[float, float]:
        base = self._base()
        return base.cdf(self.low), 1.0 if self.high is None else base.cdf(self.high)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        lo, hi = self._cdf_bounds()
        return self._base().ppf(lo + (hi - lo) * rng.uniform(size=n))

    def cdf(self, x: np.ndarray) -> np.ndarray:
        base = self._base()
        lo, hi = self._cdf_bounds()
        return np.clip((base.cdf(x) - lo) / (hi - lo), 0.0, 1.0)


Distribution = Annotated[Constant | Uniform | TruncNormal | LogNormal, Field(discriminator="dist")]
