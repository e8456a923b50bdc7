"""Multivariate normal draws without BLAS or LAPACK: the same bits under every OpenBLAS kernel.

``numpy.random.Generator.multivariate_normal`` factors the covariance with LAPACK's SVD and multiplies with BLAS,
whose last bits depend on the kernel OpenBLAS picks for the CPU; a draw that is then rounded or cut into answer
categories can change. Here the Cholesky factor is computed in plain Python (``math.fsum``) and applied with
elementwise numpy operations only.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def cholesky(cov: Sequence[Sequence[float]]) -> list[list[float]]:
    """Lower Cholesky factor L (L L' = cov) in plain Python; ValueError if cov is not positive definite."""
    k = len(cov)
    L = [[0.0] * k for _ in range(k)]
    for i in range(k):
        for j in range(i + 1):
            s = math.fsum(L[i][m] * L[j][m] for m in range(j))
            if i == j:
                d = cov[i][i] - s
                if not d > 1e-12 * max(1.0, abs(cov[i][i])):
                    raise ValueError("the covariance matrix is not positive definite")
                L[i][j] = math.sqrt(d)
            else:
                L[i][j] = (cov[i][j] - s) / L[j][j]
    return L


def draw(L: list[list[float]], mean: Sequence[float], n: int, rng: np.random.Generator) -> np.ndarray:
    """n draws (rows) of N(mean, L L'): z ~ N(0, I) from `rng` (n x k standard normals, row by row), x = mean + L z
    column by column with elementwise operations."""
    z = rng.standard_normal((n, len(L)))
    x = np.empty_like(z)
    for i, row in enumerate(L):
        col = np.full(n, float(mean[i]))
        for j in range(i + 1):
            col += z[:, j] * row[j]
        x[:, i] = col
    return x
