"""How the core compiles its per-pixel loops: numba, with numpy as the fallback.

Each module of the core keeps its ``@kernel`` functions beside the numpy code they replace.
Where numba is installed (a pip requirement; rosdep key python3-numba) and the environment
variable FCOP_NUMBA is not 0, the modules call the kernels; else they run the numpy code. Both
give the same results up to rounding (the tests compare them on the same frames). Kernels
compile on first use (about 40 s on a 2-core machine; ``warm_up`` does it ahead), are cached on
disk (about 0.4 s to load after), and release the GIL, so the node's executor thread runs while
the estimator thread computes.
"""
from __future__ import annotations

import os

try:
    import numba
except ImportError:  # the numpy paths serve
    numba = None

#: Whether the core calls its compiled kernels (read at call time: tests switch it off).
ENABLED = numba is not None and os.environ.get("FCOP_NUMBA", "1").strip().lower() not in (
    "0", "false", "no", "off")


def describe() -> str:
    """What runs the kernels, for logs and diagnostics."""
    if ENABLED:
        return f"numba {numba.__version__}"
    return "numpy (numba not installed)" if numba is None else "numpy (compiled kernels off)"


#: Every kernel defined, for ``warm_up``'s check that it reached them all.
KERNELS: list = []


def kernel(fn):
    """Compile ``fn`` with numba (lazily, cached, without the GIL) when numba is installed;
    without numba ``fn`` is returned as it is and its module uses its numpy path instead."""
    if numba is None:
        return fn
    compiled_fn = numba.njit(cache=True, nogil=True, error_model="numpy")(fn)
    KERNELS.append(compiled_fn)
    return compiled_fn


def kernel_helper(fn):
    """Mark a function that kernels call (not Python): compiled into each kernel that calls it
    (numba's register_jitable), not a kernel of its own and not listed in KERNELS, because a
    kernel loaded from the disk cache never compiles its callees, so ``warm_up`` would not
    reach them."""
    if numba is None:
        return fn
    from numba.extending import register_jitable

    return register_jitable(fn)


def reassociating_helper(fn):
    """Compile ``fn``, a sum-heavy helper that kernels call, with its floating-point sums free
    to be reordered (LLVM's reassoc flag alone), so that the compiler splits each reduction
    into vector lanes: the results differ from a sequential sum in the last bits, as BLAS's do.
    A function of its own (its flags are not the caller's), compiled into each kernel that
    calls it; like kernel_helper, not listed in KERNELS. Without numba, ``fn`` as it is."""
    if numba is None:
        return fn
    return numba.njit(cache=True, nogil=True, error_model="numpy",
                      fastmath={"reassoc"})(fn)


def warm_up() -> float:
    """Compile (or load from the cache) every kernel by estimating one small synthetic frame;
    returns the seconds it took. A no-op when the kernels are not used."""
    import time

    import numpy as np

    if not ENABLED:
        return 0.0
    from .estimator import estimate_focal

    t = time.perf_counter()
    h, w, f = 120, 160, 150.0
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 1.0 + 0.002 * xx + 0.001 * yy
    mask = np.zeros((h, w), np.int32)
    mask[20:70, 20:70] = 1
    mask[60:110, 90:150] = 2
    # Two tilted planes seen through the camera, each one's points scaled into the unit cube
    # as its NOCS.
    X = np.stack([(xx - w / 2) * depth / f, (yy - h / 2) * depth / f, depth], -1)
    nocs = np.zeros_like(X)
    for k in (1, 2):
        Xk = X[mask == k] - X[mask == k].mean(0)
        nocs[mask == k] = 0.5 + Xk / (2.2 * np.abs(Xk).max())
    # A little noise, so that the denoising kernels run too.
    noise = np.random.default_rng(0)
    depth = depth * (1.0 + 0.002 * noise.standard_normal(depth.shape))
    nocs = np.where(mask[..., None] > 0, nocs + 0.01 * noise.standard_normal(nocs.shape), 0.0)
    est = estimate_focal(depth, nocs, mask, seed=0)
    if est.focal is None:
        raise RuntimeError(f"compiled.warm_up: the warm-up frame gave no focal ({est.reason})")
    # The node's images are float32, which the correspondences kernel reads as they are.
    estimate_focal(depth.astype(np.float32), nocs.astype(np.float32), mask, seed=0)
    # solve_triplets on its own (the RANSAC method's hypotheses): the votes kernel compiled
    # the triplet kernel into itself, not as a signature of its own.
    from .solver import solve_triplets

    on = mask > 0
    pixels = X[on][:, :2] * f / X[on][:, 2:]
    solve_triplets(pixels, depth[on], nocs[on], np.arange(9).reshape(3, 3))
    return time.perf_counter() - t
