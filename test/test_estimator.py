"""The frame estimate on rendered frames: exactness, invariance, noise presets, bad input."""
import numpy as np
import pytest

from fcop_ros import (
    EstimatorOptions,
    FocalEstimate,
    NoiseBound,
    WindowOptions,
    estimate_focal,
    estimate_poses,
)
from fcop_ros.core.pose import rotation_angle_deg
from fcop_ros.synthetic.scenes import BAD_CASES, clean_frame, corrupted, noisy_frame
from fcop_ros.synthetic.world import world_frame


def _match(est, frame):
    truth = {o.instance_id: o for o in frame.objects}
    return [(o, truth[o.instance_id]) for o in est.objects if o.instance_id in truth]


@pytest.mark.parametrize("seed", range(6))
def test_clean_frames_exact_focal_and_poses(seed):
    fr = clean_frame(seed)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=seed)
    assert isinstance(est, FocalEstimate)
    assert abs(est.focal / fr.focal - 1) < 1e-3
    pairs = _match(est, fr)
    visible = [o for o in fr.objects if (fr.mask == o.instance_id).sum() >= 200]
    assert len(pairs) >= len(visible) >= 3
    for got, true in pairs:
        assert np.abs(got.rotation - true.rotation).max() < 1e-3
        assert np.linalg.norm(got.translation - true.translation) < 1e-3
        assert abs(got.scale / true.scale - 1) < 1e-3


def test_pose_stage_is_a_function_of_the_instances_and_a_focal():
    """estimate_poses after the frame estimate (poses=False) at the frame's focal length gives
    the poses estimate_focal attaches itself; a longer focal length draws them to the axis."""
    fr = noisy_frame(2, "moderate")
    with_poses = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    assert est.objects == [] and est.instances and est.focal == with_poses.focal
    got = estimate_poses(est.instances, est.focal, exclude=est.mirrored)
    assert [o.instance_id for o in got] == [o.instance_id for o in with_poses.objects]
    for a, b in zip(got, with_poses.objects):  # the same up to the fits' random pixel subsets
        assert a.scale == pytest.approx(b.scale, rel=0.01)
        assert np.linalg.norm(a.translation - b.translation) < 0.01 * np.linalg.norm(b.translation)
    longer = estimate_poses(est.instances, 1.1 * est.focal)
    for a, b in zip(got, longer):  # depth stays, the lateral offset shrinks as 1 / f
        lateral = np.linalg.norm(a.translation[:2]) / 1.1
        assert np.linalg.norm(b.translation[:2]) == pytest.approx(lateral, rel=0.02)
    skip = got[0].instance_id
    kept = estimate_poses(est.instances, est.focal, exclude=[skip])
    assert skip not in [o.instance_id for o in kept]
    assert estimate_poses([], 600.0) == []


def test_global_depth_scale_leaves_focal_unchanged():
    for seed, preset in [(1, "clean"), (2, "moderate"), (3, "harsh")]:
        fr = noisy_frame(seed, preset)
        base = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0)
        for k in (0.5, 1.3, 4.0):
            scaled = estimate_focal(fr.depth * k, fr.nocs, fr.mask, seed=0)
            # Exact up to float32 rounding in the denoising filters (measured: <= 6e-5).
            assert scaled.focal == pytest.approx(base.focal, rel=1e-4)
            assert scaled.inlier_count == base.inlier_count
            # The scale goes into the objects' metric size, and their translation scales with it.
            for a, b in zip(base.objects, scaled.objects):
                assert b.scale == pytest.approx(k * a.scale, rel=2e-4)


def test_additive_depth_offset_does_bias_focal():
    """The equation is not offset-invariant: a 10 cm offset at ~1 m must move the estimate."""
    fr = clean_frame(4)
    base = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0).focal
    shifted = estimate_focal(fr.depth + 0.1, fr.nocs, fr.mask, seed=0).focal
    assert abs(shifted / base - 1) > 0.02


def test_principal_point_can_be_given():
    fr = clean_frame(5)
    cx, cy = fr.principal_point
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, principal_point=(cx, cy), seed=0)
    assert est.principal_point == (cx, cy) and abs(est.focal / fr.focal - 1) < 1e-3
    wrong = estimate_focal(fr.depth, fr.nocs, fr.mask, principal_point=(cx + 60, cy - 40), seed=0)
    assert abs(wrong.focal / fr.focal - 1) > abs(est.focal / fr.focal - 1)


def test_ransac_leaves_f_to_the_depth_s_shape_not_its_units():
    """The paper's RANSAC threshold is in metres, so the same frame in millimetres gave another
    focal (a user's seed 1: 4874 px in metres, 18330 in millimetres, 1624 in kilometres); it is
    now relative to each object's depth, and the three agree."""
    opt = EstimatorOptions(method="ransac")
    fr = noisy_frame(1, "moderate")
    got = [estimate_focal(fr.depth * k, fr.nocs, fr.mask, options=opt, seed=0).focal
           for k in (1.0, 1000.0, 0.001)]
    assert got[0] is not None and got[1] == pytest.approx(got[0], rel=1e-5)
    assert got[2] == pytest.approx(got[0], rel=1e-5)


def test_ransac_variant_is_selectable():
    fr = clean_frame(0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, options=EstimatorOptions(method="ransac"),
                         seed=0)
    assert est.method == "ransac" and abs(est.focal / fr.focal - 1) < 0.01 and est.objects


def test_ransac_without_a_supporting_pixel_gives_no_focal():
    """A threshold no pixel meets: no focal, and the reason says why (it gave 637 px with 0
    inliers)."""
    fr = noisy_frame(0, "mild")
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0,
                         options=EstimatorOptions(method="ransac", ransac_threshold=1e-12))
    assert est.focal is None and "no RANSAC hypothesis has a pixel within" in est.reason


def test_options_that_would_break_an_estimate_are_refused_where_they_are_set():
    """An infinite noise bound crashed estimate_focal; an infinite object_tau (or any error
    term) made every std_rel infinite; a focal given as a string or a bool was taken."""
    with pytest.raises(ValueError, match="noise bound must be finite"):
        NoiseBound(np.inf, "absolute")
    for name in ("object_tau", "shape_error", "unseen_depth_error", "object_tau_weight"):
        with pytest.raises(ValueError, match=f"{name} must be finite"):
            EstimatorOptions(**{name: np.inf})
    fr = clean_frame(0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    for bad in ("600", True):
        with pytest.raises(TypeError, match="focal must be a number of pixels"):
            estimate_poses(est.instances, bad)
    assert len(estimate_poses(est.instances, est.focal, exclude=None)) == len(est.instances)
    with pytest.raises(ValueError, match=r"focal_range must be \(min, max\)"):
        EstimatorOptions(focal_range=(50, 100, 2000))


def test_literal_paper_method_on_clean_frame():
    """Absolute 5 px bound, no refinement, no denoising: the paper's fCOP-IS."""
    fr = clean_frame(0)
    opt = EstimatorOptions(noise_bound=NoiseBound(5.0, "absolute"), refine=False,
                           denoise_radius=0, erode_px=0, outlier_sigma=0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, options=opt, seed=0)
    assert abs(est.focal / fr.focal - 1) < 0.01 and est.interval[0] <= est.focal <= est.interval[1]


def _errors(preset, seeds, opt=None):
    focal, rot, trans = [], [], []
    for s in seeds:
        fr = noisy_frame(s, preset)
        est = estimate_focal(fr.depth, fr.nocs, fr.mask, options=opt, seed=s)
        focal.append(np.nan if est.focal is None else 100 * abs(est.focal / fr.focal - 1))
        for got, true in _match(est, fr):
            rot.append(rotation_angle_deg(got.rotation, true.rotation))
            trans.append(
                100
                * np.linalg.norm(got.translation - true.translation)
                / np.linalg.norm(true.translation)
            )
    return np.array(focal), np.array(rot), np.array(trans)


# Measured on 40 seeded frames (seeds 0..39) with the default options, commit of this test:
# preset: (median focal %, p90 focal %, median rotation deg, median translation % of distance).
# Bounds below are these numbers plus a margin of ~25%. These old presets were what the
# previous estimator was tuned on; the per-object fit with a depth tilt trades a little here for
# far less bias on the randomised world (test_world_accuracy.py). Re-measured when the presets
# became fixed settings of the world's error mechanisms (other random draws, a smooth depth
# field normalised to its nominal amplitude); before: mild (0.40, 1.42, 0.22, 5.7), moderate
# (1.05, 2.61, 0.48, 11.4), harsh (4.72, 12.15, 1.76, 22.3). Re-measured again when the NOCS
# were regression-calibrated for their noise; before: mild (0.62, 1.71, 0.24, 3.0), moderate
# (1.21, 4.64, 0.54, 6.2), harsh (4.61, 9.88, 1.74, 12.8). Re-measured when the unseen-depth
# term came to follow each fit's lean on depth (the objects' weights changed); before: mild
# (0.64, 1.58, 0.24, 3.0), moderate (1.17, 4.03, 0.51, 6.2), harsh (3.02, 6.96, 1.41, 12.5).
# Re-measured when the objects came to be weighted by their fits' noise; before: mild (0.68,
# 1.63, 0.23, 3.1), moderate (1.23, 4.66, 0.52, 6.2), harsh (3.39, 7.11, 1.41, 12.2).
MEASURED = {
    "mild": (0.47, 1.03, 0.22, 3.0),
    "moderate": (1.10, 2.74, 0.47, 6.2),
    "harsh": (2.44, 6.17, 1.40, 12.1),
}


@pytest.mark.parametrize("preset", sorted(MEASURED))
def test_noise_presets_regression(preset):
    focal, rot, trans = _errors(preset, range(40))
    med, p90, rmed, tmed = MEASURED[preset]
    assert np.isnan(focal).sum() == 0
    assert np.median(focal) <= 1.25 * med
    assert np.percentile(focal, 90) <= 1.25 * p90
    assert np.median(rot) <= 1.25 * rmed
    assert np.median(trans) <= 1.25 * tmed


class TestBadInput:
    def setup_method(self):
        fr = clean_frame(0)
        self.depth, self.nocs, self.mask = fr.depth, fr.nocs, fr.mask

    def test_mismatched_shapes(self):
        with pytest.raises(ValueError, match="sizes differ"):
            estimate_focal(self.depth[:-1], self.nocs, self.mask)
        with pytest.raises(ValueError, match="nocs must be"):
            estimate_focal(self.depth, self.nocs[..., :2], self.mask)
        with pytest.raises(ValueError, match="depth must be"):
            estimate_focal(self.depth[..., None], self.nocs, self.mask)
        with pytest.raises(ValueError, match="integer instance ids"):
            estimate_focal(self.depth, self.nocs, self.mask.astype(float))

    def test_unknown_or_invalid_option(self):
        with pytest.raises(TypeError, match="triplets"):
            EstimatorOptions(triplets=5)
        with pytest.raises(ValueError, match="focal_range"):
            EstimatorOptions(focal_range=(100, 10))
        with pytest.raises(ValueError, match="noise bound"):
            NoiseBound(0.8, "relative")
        with pytest.raises(ValueError, match="shape_error"):
            EstimatorOptions(shape_error=-0.01)
        # Each of these was accepted and failed later, or silently did something else.
        for bad, match in ((dict(min_inlier_ratio=2), "min_inlier_ratio"),
                           (dict(min_fit_quality=5), "min_fit_quality"),
                           (dict(erode_px=-1), "erode_px"),
                           (dict(denoise_radius=-3), "denoise_radius"),
                           (dict(outlier_sigma=-1), "outlier_sigma"),
                           (dict(pose_max_std=-1), "pose_max_std"),
                           (dict(triplets_per_object=2.5), "triplets_per_object"),
                           (dict(min_nocs_spread=float("nan")), "min_nocs_spread")):
            with pytest.raises(ValueError, match=match):
                EstimatorOptions(**bad)
        with pytest.raises(TypeError, match="refine"):
            EstimatorOptions(refine=1)
        for bad, match in ((dict(min_window_votes=-5), "min_window_votes"),
                           (dict(max_frames=2.5), "max_frames")):
            with pytest.raises(ValueError, match=match):
                WindowOptions(**bad)
        with pytest.raises(TypeError, match="options=EstimatorOptions"):
            estimate_focal(self.depth, self.nocs, self.mask, EstimatorOptions())
        with pytest.raises(TypeError, match="options=EstimatorOptions"):
            estimate_focal(self.depth, self.nocs, self.mask, options={"refine": False})

    @pytest.mark.parametrize("case", sorted(BAD_CASES))
    def test_no_evidence_gives_none(self, case):
        fr = corrupted(clean_frame(0), case)
        depth, nocs, mask = fr.depth, fr.nocs, fr.mask
        est = estimate_focal(depth, nocs, mask, seed=0)
        assert est.focal is None and est.reason
        assert est.objects == []

    def test_one_pixel_image(self):
        est = estimate_focal(np.ones((1, 1)), np.full((1, 1, 3), 0.5), np.ones((1, 1), np.uint8))
        assert est.focal is None


@pytest.mark.parametrize("numba", [True, False])
def test_votes_all_outside_focal_range_are_named_as_such(numba, monkeypatch):
    """Votes that exist but all fall outside focal_range say so, not 'degenerate geometry'; the
    numbers of an estimate are not changed by telling why there is none."""
    from fcop_ros.core import compiled
    monkeypatch.setattr(compiled, "ENABLED", numba and compiled.ENABLED)
    fr = clean_frame(0, 640, 480, 300.0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask,
                         options=EstimatorOptions(focal_range=(400.0, 2000.0)), seed=3)
    assert est.focal is None
    assert est.reason.startswith("all ") and "focal votes outside focal_range [400, 2000]" in \
        est.reason, est.reason
    n = int(est.reason.split()[1])
    assert n > 1000
    ok = estimate_focal(fr.depth, fr.nocs, fr.mask,
                        options=EstimatorOptions(focal_range=(50.0, 2000.0)), seed=3)
    assert abs(ok.focal / 300.0 - 1) < 1e-3 and ok.votes.size == n  # the same triplets
    # Degenerate geometry is still called so: one NOCS point for every pixel gives no vote.
    same = np.where(fr.mask[..., None] > 0, 0.5, 0.0) * np.ones(3)
    est = estimate_focal(fr.depth, same, fr.mask, seed=3)
    assert est.focal is None and "outside focal_range" not in est.reason, est.reason


def test_object_extents_follow_a_zoom_cut_objects_too():
    """Ten sensor-preset scenes seen at f and 1.25 f from the same place: each whole object's
    extent (image scale x median depth) grows by 1.227-1.276. An object the image's edge cuts
    in either view has an extent too since 25 Nov 2026: its image radius and NOCS radius are
    of the part in view, so a zoom that cuts more of it still scales it, by a median 1.23 of
    17 (0.93-1.26: what the edge takes changes the part's shape; 1.23 of 16 before the sensor
    preset's lens). Before the image scale was
    taken over the NOCS radius (93ab5e5) a cut object's scale moved with the cut (seed 41:
    0.96 and 0.97), and cut objects had none."""
    from fcop_ros.synthetic.world import world_frames

    whole, cut = [], []
    for seed in range(40, 50):
        seq = world_frames("sensor", seed, 2, orbit_deg=0.0, zoom_frame=1, zoom_factor=1.25)
        before, after = (estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
                         for fr in seq.frames)
        h, w = seq.frames[0].mask.shape

        def at_edge(mask, i):
            rows, cols = np.nonzero(mask == i)
            return rows.min() == 0 or cols.min() == 0 or rows.max() == h - 1 or cols.max() == w - 1

        for i in set(before.object_extents) & set(after.object_extents):
            ratio = after.object_extents[i] / before.object_extents[i]
            edge = any(at_edge(fr.mask, i) for fr in seq.frames)
            (cut if edge else whole).append(ratio)
    assert len(whole) == 19 and 1.22 < min(whole) and max(whole) < 1.28
    assert len(cut) == 17 and abs(np.median(cut) - 1.22) < 0.01 and min(cut) > 0.9


def test_nocs_in_0_255_are_named_as_the_reason():
    """NOCS as 8-bit values (0..255) lie outside [0, 1] on every object pixel; the frame is
    refused and the reason says why instead of reading like empty masks. NOCS in [0, 1] never
    get the hint."""
    fr = clean_frame(0)
    est = estimate_focal(fr.depth, fr.nocs * 255.0, fr.mask, seed=0, poses=False)
    assert est.focal is None
    assert est.reason.startswith("NOCS outside [0, 1] on 100% of the object pixels sampled")
    assert "they must lie in [0, 1]: divide 8-bit NOCS by 255" in est.reason
    tiny = np.zeros_like(fr.mask)
    tiny[200:206, 300:306] = 1  # on an object: too few pixels, valid NOCS
    est = estimate_focal(fr.depth, fr.nocs, tiny, seed=0, poses=False)
    assert est.reason == "no instance with >= 50 valid pixels"
    est = estimate_focal(fr.depth, fr.nocs * 255.0, tiny, seed=0, poses=False)
    assert "divide 8-bit NOCS by 255" in est.reason  # too few pixels to sample: still named


@pytest.mark.parametrize("name, change", [
    ("centred", lambda n, has: np.where(has, n - 0.5, 0.0)),
    ("doubled", lambda n, has: n * 2.0),
])
def test_nocs_in_another_convention_are_refused_not_half_used(name, change):
    """Centred NOCS ([-0.5, 0.5]) or NOCS scaled by 2 lie outside [0, 1] on about half of the
    object pixels. Those were dropped one by one and the rest, a biased half of each object,
    gave a focal length 10-24% off on the frames a user tried; now the frame is refused with the
    share and the values seen (measured: 43-57% of the sampled pixels on these frames)."""
    for seed in range(3):
        fr = world_frame("predicted", 600 + seed)
        has = (fr.nocs != 0).any(2)[..., None]
        est = estimate_focal(fr.depth, change(fr.nocs, has), fr.mask, seed=0, poses=False)
        assert est.focal is None
        assert est.reason.startswith("NOCS outside [0, 1] on ")
        if name == "centred":
            assert "add 0.5" in est.reason
        assert estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False).focal


def test_the_reason_names_the_input_that_lacks_what_it_needs():
    fr = clean_frame(0)
    has = (fr.nocs != 0).any(2)
    cases = {
        "the mask has no instance": (fr.depth, fr.nocs, np.zeros_like(fr.mask)),
        "the depth is invalid (NaN, inf or <= 0) on every object pixel": (
            np.where(fr.mask > 0, np.nan, fr.depth), fr.nocs, fr.mask),
        "the NOCS are zero or not finite (no prediction) on every object pixel": (
            fr.depth, np.where(has[..., None], 0.0, fr.nocs), fr.mask),
    }
    for start, (d, n, m) in cases.items():
        est = estimate_focal(d, n, m, seed=0, poses=False)
        assert est.focal is None and est.reason.startswith(start), est.reason


def test_depth_as_integers_and_a_bad_principal_point_are_refused():
    """A uint16 depth is millimetres (16UC1): taken as metres, f came out right but poses and
    extents 1000x too large. A principal point that is not two finite numbers on the image is
    a slip (before: a silent wrong estimate, or an unrelated reason)."""
    fr = clean_frame(0)
    mm = np.nan_to_num(fr.depth * 1000).astype(np.uint16)
    with pytest.raises(ValueError, match="millimetres"):
        estimate_focal(mm, fr.nocs, fr.mask, seed=0)
    for pp, match in (((-10.0, 240.0), "outside the 640x480"), ((5000, -300), "outside"),
                      ((np.nan, 240.0), "finite"), ((1, 2, 3), "two numbers"), (5, "two numbers")):
        with pytest.raises(ValueError, match=match):
            estimate_focal(fr.depth, fr.nocs, fr.mask, pp, seed=0)
    assert estimate_focal(fr.depth, fr.nocs, fr.mask, (300.0, 250.0), seed=0).principal_point == (
        300.0, 250.0)


def test_mask_ids_beyond_signed_64_bits_are_refused():
    """Before, uint64 ids of 2**63 and above read as background ('no instance with >= 50 valid
    pixels'); ids below that are taken as they are."""
    fr = clean_frame(0)
    huge = fr.mask.astype(np.uint64)
    huge[huge > 0] += np.uint64(2**63)
    with pytest.raises(ValueError, match="2\\*\\*63"):
        estimate_focal(fr.depth, fr.nocs, huge, seed=0)
    large = fr.mask.astype(np.uint64)
    large[large > 0] += np.uint64(2**40)
    assert estimate_focal(fr.depth, fr.nocs, large, seed=0, poses=False).focal


def test_estimate_poses_refuses_a_focal_that_is_no_focal():
    """Before, 0, -600, NaN and inf gave [] without a word and None a bare TypeError."""
    fr = clean_frame(0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    for bad in (0.0, -600.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="focal"):
            estimate_poses(est.instances, bad)
    with pytest.raises(TypeError, match="focal"):
        estimate_poses(est.instances, None)
    assert len(estimate_poses(est.instances, est.focal)) == len(est.instances)


def test_estimates_compare_by_identity_and_a_long_reason_is_cut():
    """An estimate holds arrays, so == between two raised numpy's 'truth value of an array is
    ambiguous'; it now compares by identity. A frame of 294 instances whose NOCS explain none
    gave a 5 kB reason; it lists eight and counts the rest."""
    fr = clean_frame(0)
    a = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    b = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    assert a == a and a != b
    yy, xx = np.mgrid[0:480, 0:640]
    mask = (yy // 24 * 27 + xx // 24 + 1).astype(np.int32)  # 540 tiles of 24x24 px
    rng = np.random.default_rng(0)
    nocs = rng.random((480, 640, 3)) * 0.9 + 0.05
    depth = 1.0 + 0.001 * rng.random((480, 640))
    est = estimate_focal(depth, nocs, mask, seed=0, poses=False)
    assert est.focal is None and len(est.reason) < 1500, est.reason[:200]


def test_a_depth_offset_biases_the_focal_beyond_what_std_rel_says():
    """A known limit, as the README states it: an additive depth offset (or depth from a
    relative-depth network: scale and shift) moves f by about offset / distance, and no
    residual shows it. Measured on noisy_frame(5, 8, 11, 'mild'), objects ~0.7 m away: +0.05 m
    gives +7.1 / +6.3 / +5.4% at std_rel 2.7 / 2.6 / 2.7%; 0.5 d + 0.3 gives +61 / +62 / +53% at
    3.7 / 4.5 / 4.8% (with object_tau 0.066; at 0.005: +7.3 / +6.5 / +5.6% at 1.3 / 0.6 / 1.4%
    and +83 / +86 / +71% at 3.0 / 3.9 / 4.0%: the wider prior keeps more objects together)."""
    for seed in (5, 8, 11):
        fr = noisy_frame(seed, "mild")
        for depth, least, beyond in ((fr.depth + 0.05, 0.05, 1.8), (0.5 * fr.depth + 0.3, 0.5, 8)):
            est = estimate_focal(depth, fr.nocs, fr.mask, seed=1)
            err = np.log(est.focal / fr.focal)
            assert err > least and err > beyond * est.std_rel, (seed, err, est.std_rel)


def test_an_erosion_wider_than_any_image_is_refused():
    """erode_px had no upper bound and costs a pass per pixel of it: erode_px=10**9 never
    returned. An erosion beyond half the largest image side removes every object."""
    from fcop_ros.core.options import MAX_ERODE_PX
    assert EstimatorOptions(erode_px=MAX_ERODE_PX).erode_px == MAX_ERODE_PX
    for bad in (MAX_ERODE_PX + 1, 10**9):
        with pytest.raises(ValueError, match=rf"erode_px must be an integer in \[0, "
                                             rf"{MAX_ERODE_PX}\]"):
            EstimatorOptions(erode_px=bad)


def test_options_that_refuse_every_object_say_so():
    """Settings accepted and then refusing every object read like faults of the frame:
    fit_iterations=1 ('degenerate fit': one iteration takes no step) is refused where it is
    set; max_pixels below min_object_pixels ('no instance with >= 50 valid pixels') and
    min_fit_quality=1.0 ('explain 100% (< 100%): not the predicted category') are named in
    the reason: the node allows min_object_pixels above max_pixels, and exact NOCS meet 1.0."""
    with pytest.raises(ValueError, match="fit_iterations must be an integer >= 2"):
        EstimatorOptions(fit_iterations=1)
    fr = clean_frame(0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0,
                         options=EstimatorOptions(max_pixels=10, min_object_pixels=50))
    assert est.focal is None
    assert "min_object_pixels=50 is above max_pixels=10" in est.reason, est.reason
    fr = noisy_frame(2, "moderate")
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0,
                         options=EstimatorOptions(min_fit_quality=1.0))
    assert est.focal is None and est.rejected
    poor = [why for why in est.rejected.values() if "NOCS explain" in why]
    assert poor and all("below min_fit_quality=1 (the default 0.85 keeps it)" in why
                        and "100" not in why for why in poor), est.rejected


def test_the_nocs_range_hint_fits_the_image_type():
    """16-bit NOCS were told to 'divide 8-bit NOCS by 255'; the hint follows the image's type,
    and floats beyond 255 get the range alone."""
    fr = clean_frame(0)
    tiny = np.zeros_like(fr.mask)
    tiny[200:206, 300:306] = 1  # too few pixels to sample: the hint comes with the pixel count
    for dtype, words in ((np.uint16, "divide 16-bit NOCS by 65535"),
                         (np.uint8, "divide 8-bit NOCS by 255")):
        nocs = (fr.nocs * np.iinfo(dtype).max).astype(dtype)
        for mask in (fr.mask, tiny):
            est = estimate_focal(fr.depth, nocs, mask, seed=0)
            assert est.focal is None and words in est.reason, est.reason
    est = estimate_focal(fr.depth, fr.nocs * 1000.0, fr.mask, seed=0)
    assert est.reason.endswith("they must lie in [0, 1])"), est.reason


def test_one_object_with_a_lost_channel_is_named_as_several_are():
    """One object whose NOCS lost a channel was refused with the shape wording ('its NOCS
    explain 83% ...: not the predicted category'); several get the lost-channel wording."""
    fr = clean_frame(2)
    ids = [i for i in np.unique(fr.mask) if i > 0]
    has = (fr.nocs != 0).any(2)
    flat = fr.nocs.copy()
    flat[..., 0] = np.where(has, 0.5, 0.0)
    words = "NOCS channel 0 is 0.500 on every object: a lost channel? the frame is refused ("
    for keep in (ids[:1], ids[1:2], ids):
        mask = np.where(np.isin(fr.mask, keep), fr.mask, 0)
        est = estimate_focal(fr.depth, flat, mask, seed=0, poses=False)
        assert est.focal is None and est.reason.startswith(words), (keep, est.reason)



def test_a_thin_object_erosion_removed_and_a_small_piece_are_named_as_such():
    """A new user's trials. A strip one pixel high (44 valid pixels) that the mask's erosion
    empties was refused as having too few valid pixels; the reason now names the erosion. A
    10x10 piece of one object (its NOCS span 0.012, every channel nearly constant) was refused
    as "a lost channel?"; it is a piece too small to tell, and the reason says that alone."""
    fr = clean_frame(2)
    ys, xs = np.nonzero(fr.mask == 1)
    y, x = ys[len(ys) // 2], xs[len(ys) // 2]
    strip = np.zeros_like(fr.mask)
    strip[y, x - 30:x + 30] = 1
    strip[fr.mask != 1] = 0
    n = int(strip.sum())
    est = estimate_focal(fr.depth, fr.nocs, strip, options=EstimatorOptions(min_object_pixels=3),
                         seed=0, poses=False)
    assert est.focal is None and est.reason == (
        f"no instance with >= 3 valid pixels after eroding each mask by erode_px=1 (the largest "
        f"had {n} before: a small or thin object; lower erode_px)"), est.reason
    piece = np.zeros_like(fr.mask)
    yc, xc = int(np.median(ys)), int(np.median(xs))
    piece[yc - 5:yc + 5, xc - 5:xc + 5] = 1
    piece[fr.mask != 1] = 0
    est = estimate_focal(fr.depth, fr.nocs, piece, seed=1, poses=False)
    assert est.focal is None and "lost channel" not in est.reason, est.reason
    assert "too small a piece of the category's shape" in est.reason, est.reason


def test_a_principal_point_of_bools_is_refused():
    """(True, False) was taken as (1.0, 0.0) and ("320", "240") as numbers: neither is a pair of
    coordinates; numpy's numbers are."""
    fr = clean_frame(0)
    for pp in ((True, False), (np.True_, 240.0), ("320", "240")):
        with pytest.raises(ValueError, match="two numbers"):
            estimate_focal(fr.depth, fr.nocs, fr.mask, pp, seed=0)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, (np.float32(320), np.int64(240)), seed=0)
    assert est.principal_point == (320.0, 240.0)




def test_depth_far_outside_metres_is_refused_and_units_slips_are_not():
    """Depth of 1e-9 or 1e100 times a scene's gave 1078 px for 629 (the fit's floors are in
    metres) or 'degenerate geometry'; 1e300 raised OverflowError. Millimetres for metres (x1000)
    and back (x0.001) give the same focal; depth whose objects' median is outside 1e-4 .. 1e6 m
    is refused with the reason."""
    fr = clean_frame(1)
    base = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False).focal
    for k in (1e-3, 1e3):
        est = estimate_focal(fr.depth * k, fr.nocs, fr.mask, seed=0, poses=False)
        assert est.focal == pytest.approx(base, rel=1e-9)
    for k in (1e-9, 1e-5, 1e7, 1e100, 1e300):
        est = estimate_focal(fr.depth * k, fr.nocs, fr.mask, seed=0, poses=False)
        assert est.focal is None and "outside 0.0001 .. 1e+06 m" in est.reason, (k, est.reason)


def test_an_occlusion_moves_an_objects_image_scale_little():
    """The image scale of an object (its RMS image radius over its NOCS' RMS radius), which the
    window judges a zoom by, stays where it was when half of the object is hidden: 37 objects of
    ten sensor-preset scenes (the whole ones and, since 25 Nov 2026, those the image's edge cuts;
    36 before the preset's lens) with the pixels left of their median column taken off the mask
    (as a nearer object would) moved by -4.1% in the median (log), 16% at most, where their
    image radius alone shrank by 0.20 in the median (0.40 at most), as a zoom of 0.82 would
    shrink it. Static sequence 7015
    restarted the window on such an occlusion before."""
    from fcop_ros.synthetic.world import world_frame

    scale, radius = [], []
    for seed in range(40, 50):
        fr = world_frame("sensor", seed)
        full = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
        for i in full.object_radii:
            mask = fr.mask.copy()
            cols = np.nonzero(mask == i)[1]
            mask[(mask == i) & (np.arange(mask.shape[1]) < np.median(cols))] = 0
            part = estimate_focal(fr.depth, fr.nocs, mask, seed=0, poses=False)
            if i in part.object_radii:
                scale.append(np.log(part.object_radii[i] / full.object_radii[i]))
                r0, r1 = (np.nonzero(m == i) for m in (fr.mask, mask))
                radius.append(0.5 * np.log((np.var(r1[0]) + np.var(r1[1]))
                                           / (np.var(r0[0]) + np.var(r0[1]))))
    assert len(scale) == 37
    assert abs(np.median(scale)) < 0.06 and np.max(np.abs(scale)) < 0.2
    assert np.median(radius) < -0.15
