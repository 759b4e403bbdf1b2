"""report.png of fcop_replay: the published focal length over time with its ±2σ band and the
truth, and below it the signed error (matplotlib, drawn off-screen)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .replay_base import ReplaySummary, output_head


# What savefig puts first in a PNG: the signature, IHDR, then matplotlib's Software tag.
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_MATPLOTLIB_TAG = b"tEXtSoftware\x00Matplotlib"


def not_a_report(path: Path) -> str:
    """Why ``path`` is not a report.png a replay could have written ('' when it is, or is
    empty or absent): a PNG with matplotlib's Software tag. A replay replaces its own report,
    never a user's image of that name."""
    head, why = output_head(path, 256)
    if head is None:
        return why
    if not head or (head.startswith(_PNG_SIGNATURE) and _MATPLOTLIB_TAG in head):
        return ""
    return "a PNG matplotlib did not write" if head.startswith(_PNG_SIGNATURE) else "not a PNG"


def write_report(path: Path, rows, summary: ReplaySummary) -> None:
    """report.png: the published focal estimate over time with its ±2σ band (σ = the window's
    relative standard error std_rel) and the truth; below, the signed error against the truth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(
        2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]}
    )
    has_truth = any("focal_true" in r for r in rows)
    if rows:
        t = (np.array([r["stamp_ns"] for r in rows]) - rows[0]["stamp_ns"]) * 1e-9
        f = np.array([r["focal"] for r in rows])
        sd = np.array(
            [np.nan if r.get("std_rel") is None else r["std_rel"] for r in rows], dtype=float
        )
        med = f", median σ {100 * np.nanmedian(sd):.2g}%" if np.isfinite(sd).any() else ""
        ax.fill_between(
            t,
            f * (1 - 2 * sd),
            f * (1 + 2 * sd),
            color="tab:blue",
            alpha=0.25,
            step="post",
            linewidth=0,
            label=f"±2σ (σ = window std_rel{med})",
        )
        ax.plot(t, f, color="tab:blue", drawstyle="steps-post", label="published focal (window)")
        if has_truth:
            tt = np.array([ti for ti, r in zip(t, rows) if "focal_true" in r])
            ft = np.array([r["focal_true"] for r in rows if "focal_true" in r])
            ax.plot(tt, ft, "k--", drawstyle="steps-post", label="truth")
            err = np.array([r["focal_error_pct"] for r in rows if "focal_true" in r])
            band = 200.0 * np.array([sd[i] for i, r in enumerate(rows) if "focal_true" in r])
            ax2.fill_between(
                tt,
                -band,
                band,
                color="tab:blue",
                alpha=0.25,
                step="post",
                linewidth=0,
                label="±2σ",
            )
            ax2.plot(tt, err, color="tab:red", drawstyle="steps-post", label="estimate − truth")
            ax2.axhline(0.0, color="k", linewidth=0.8)
            # A robust scale, so a bias of a percent shows next to the spike of a zoom; clipped
            # points are counted in the panel.
            finite_band = band[np.isfinite(band)]
            lim = max(
                1.0,
                1.5 * float(np.percentile(np.abs(err), 90)),
                1.2 * float(finite_band.max()) if finite_band.size else 0.0,
            )
            ax2.set_ylim(-lim, lim)
            clipped = int((np.abs(err) > lim).sum())
            if clipped:
                ax2.text(
                    0.01,
                    0.04,
                    f"{clipped} estimate(s) beyond ±{lim:.1f}% off scale (max "
                    f"{np.abs(err).max():.1f}%)",
                    transform=ax2.transAxes,
                    fontsize="small",
                    color="tab:red",
                )
            ax2.legend(loc="upper right", fontsize="small")
        else:
            ax2.text(
                0.5,
                0.5,
                "no truth topic: no error to show",
                ha="center",
                va="center",
                transform=ax2.transAxes,
                color="0.4",
            )
    else:
        ax.text(
            0.5, 0.5, "no estimate was published", ha="center", va="center", transform=ax.transAxes
        )
    ax.set_ylabel("focal length [px]")
    title = (f"fcop_replay: {summary.frames_estimated} of {summary.frames_read} frames answered "
             "with a CameraInfo")
    if summary.errors_pct:
        title += f", median |error| {np.median(summary.errors_pct):.2f}%"
    ax.set_title(title)
    if rows:
        ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    ax2.set_ylabel("signed error [%]")
    ax2.set_xlabel("time since first estimate [s]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
