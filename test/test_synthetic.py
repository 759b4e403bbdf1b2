"""The renderer and noise models are what every accuracy figure rests on: check them."""
from dataclasses import replace

import numpy as np
import pytest

from fcop_ros.synthetic import PRESETS, apply_noise, render, render_scene
from fcop_ros.synthetic.render import SceneObject
from fcop_ros.synthetic.scenes import clean_frame


def test_rendered_pixels_obey_the_camera_model_exactly():
    fr = clean_frame(0)
    cx, cy = fr.principal_point
    v, u = np.nonzero(fr.mask)
    d = fr.depth[v, u]
    X = np.column_stack([d * (u - cx) / fr.focal, d * (v - cy) / fr.focal, d])
    truth = {o.instance_id: o for o in fr.objects}
    for iid in np.unique(fr.mask[fr.mask > 0]):
        o = truth[iid]
        sel = fr.mask[v, u] == iid
        pred = o.scale * (fr.nocs[v[sel], u[sel]] - 0.5) @ o.rotation.T + o.translation
        assert np.abs(pred - X[sel]).max() < 1e-9
    assert (fr.nocs[fr.mask > 0] >= 0).all() and (fr.nocs[fr.mask > 0] <= 1).all()
    assert (fr.nocs[fr.mask == 0] == 0).all()


def test_occlusion_keeps_the_nearer_object():
    R = np.eye(3)
    far = SceneObject(1, "box", R, np.array([0.0, 0.0, 2.0]), 0.5)
    near = SceneObject(2, "can", R, np.array([0.0, 0.0, 1.0]), 0.2)
    fr = render([far, near], 300.0, 160, 120)
    assert fr.mask[60, 80] == 2 and fr.depth[60, 80] < 1.0
    assert fr.mask[60, 55] == 1 and fr.depth[60, 55] > 1.5
    only_far = render([far], 300.0, 160, 120)
    assert (only_far.mask == 1).sum() > (fr.mask == 1).sum()


def test_scene_is_seeded_and_sized():
    a = render_scene(np.random.default_rng(3), 5, None, 320, 240)
    b = render_scene(np.random.default_rng(3), 5, None, 320, 240)
    assert a.depth.shape == (240, 320) and a.nocs.shape == (240, 320, 3)
    np.testing.assert_array_equal(a.mask, b.mask)
    assert len(np.unique(a.mask)) >= 4


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_noise_presets_change_what_they_say(preset):
    fr = clean_frame(1)
    noisy = apply_noise(fr, preset, np.random.default_rng(0))
    assert noisy.focal == fr.focal and noisy.objects == fr.objects
    if preset == "clean":
        np.testing.assert_array_equal(noisy.depth[fr.mask > 0], fr.depth[fr.mask > 0])
        return
    both = (fr.mask > 0) & (noisy.mask == fr.mask)
    rel = np.abs(noisy.depth[both] / fr.depth[both] - 1)
    assert np.median(rel) > 1e-4
    model = PRESETS[preset]
    assert set(np.unique(fr.mask)) <= set(np.unique(noisy.mask))  # no instance eroded away
    # Up to `blobs` spurious instances per frame (none where a blob falls only on objects or on
    # invalid depth: the one blob of moderate with seed 0 adds none).
    new = [len(set(np.unique(apply_noise(fr, preset, np.random.default_rng(s)).mask))
               - set(np.unique(fr.mask))) for s in range(4)]
    assert max(new) <= model.blobs and (sum(new) > 0) == (model.blobs > 0)
    with pytest.raises(ValueError, match="unknown noise preset"):
        apply_noise(fr, "nope", np.random.default_rng(0))


def test_world_variants_share_the_scene_and_the_strength_of_its_errors():
    """The fourteen error models (tuning and thirteen held-out) see one scene and truth per seed
    and err about as strongly: rms relative depth error of a smooth field alone and rms NOCS
    displacement per axis of a NOCS distortion alone, over 4 frames (measured, tuning /
    heldout / heldout2 / heldout3 / heldout4 / heldout5 / heldout6 / heldout7 / heldout8 /
    heldout9 / heldout10 / heldout11 / heldout12 / heldout13: depth 0.030 / 0.038 / 0.033 / 0.040
    / 0.025 / 0.036 / 0.030 / 0.037 / 0.038 / 0.039 / 0.030 / 0.030 / 0.047 / 0.030 (heldout10's,
    heldout11's and heldout13's fields are the tuning grid's; heldout12's grazing-angle error has
    the tuning field's expected rms, field times a unit Gaussian, and these seeds drew it high),
    NOCS 0.016 each (heldout11's the tuning field, heldout12's misregistered NOCS maps 0.018,
    heldout13's warp of NOCS space 0.021, its unit rms taken over the cube) but
    heldout4's, heldout7's, heldout8's, heldout9's and heldout10's 0.003 (0.0025, 0.0026):
    heldout4's stretch lies all along the one axis
    that moves f, the viewing axis, and is sized as the relief and shape families are, by its
    factor; its first version, stretched to 0.016 rms and with a surface field relative to
    depth rather than to the object, cost the paper's method 17.6% on `predicted`, against 4-6%
    on the other models and the paper's 6.87% on real data; heldout7's stretch lies all along
    an image axis, which moves f as directly, and is sized by its factor in the same way, as is
    heldout8's turn about each object's vertical axis, a stretch across the view, and
    heldout9's pull of the NOCS towards their ramp across the image, which changes their relief,
    and heldout10's bend and taper of each object's NOCS along its up axis, which would move
    them 0.0008 at heldout4's factor on its coefficients and so reach 3 nocs_field at the
    object's ends; the held-out model's quadratic warp moved the NOCS 0.002 before it was
    scaled like the others)."""
    from fcop_ros.synthetic.world import VARIANTS, ErrorFamilies, world_frame

    for v in VARIANTS:
        d, p = [], []
        for s in range(4):
            clean = world_frame(ErrorFamilies(), s, v)
            fr = world_frame("only_field", s, v)
            nf = world_frame("only_nocs_field", s, v)
            assert fr.focal == clean.focal == nf.focal
            np.testing.assert_array_equal([o.translation for o in fr.objects],
                                          [o.translation for o in clean.objects])
            obj = clean.mask > 0
            d.append(fr.depth[obj] / clean.depth[obj] - 1)
            p.append(nf.nocs[obj] - clean.nocs[obj])
        depth_rms = np.sqrt(np.mean(np.concatenate(d) ** 2))
        nocs_rms = np.sqrt(np.mean(np.concatenate(p) ** 2))
        nocs_range = ((0.002, 0.01) if v in ("heldout4", "heldout7", "heldout8", "heldout9",
                                             "heldout10") else (0.01, 0.04))
        assert 0.02 < depth_rms < 0.05 and nocs_range[0] < nocs_rms < nocs_range[1], (
            v, depth_rms, nocs_rms)
    with pytest.raises(ValueError, match="unknown error-model variant"):
        world_frame("predicted", 0, "nope")


def test_third_heldout_model_errs_with_depth_and_from_frame_to_frame():
    """heldout3's coarsest depth field is a relative error linear in depth (its correlation
    with depth is 1.0 in every frame; the tuning model's grid field measured -0.15..0.42 on the
    same frames), and its global depth scale is redrawn every frame (measured 1.021-1.071 over
    5 frames of seed 3; the tuning model keeps 1.031), the same on every pixel of a frame."""
    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    clean = world_frames(ErrorFamilies(), 3, 5, "heldout3").frames
    field = ErrorFamilies(field=0.05, field_cells=(1,), field_drift=0.6)
    for noisy, ref in zip(world_frames(field, 3, 5, "heldout3").frames, clean):
        ok = np.isfinite(noisy.depth) & np.isfinite(ref.depth)
        corr = np.corrcoef(noisy.depth[ok] / ref.depth[ok] - 1, ref.depth[ok])[0, 1]
        assert abs(corr) > 0.999
    scales = {}
    for v in ("tuning", "heldout3"):
        ref = world_frames(ErrorFamilies(), 3, 5, v).frames
        noisy = world_frames(ErrorFamilies(depth_scale=0.05), 3, 5, v).frames
        ratio = [a.depth / b.depth for a, b in zip(noisy, ref)]
        assert max(np.nanstd(r) for r in ratio) < 1e-12
        scales[v] = np.ptp([np.nanmedian(r) for r in ratio])
    assert scales["tuning"] < 1e-12 and scales["heldout3"] > 0.03, scales


def test_fourth_heldout_model_errs_with_the_objects():
    """heldout4's coarsest depth field is a quadratic in each object's true NOCS (a
    least-squares fit of the depth error on the nine monomials explains all of it per object;
    the tuning model's smooth grid field leaves 4e-5 to 1.6e-4 of its variance unexplained),
    each object's distance is redrawn every frame (only the object's pixels move, by one factor
    each), its NOCS distortion moves every pixel of an object along the viewing axis, and NOCS
    come in steps of 1/255."""
    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    def r2(noisy, ref):
        out = []
        for iid in np.unique(ref.mask[ref.mask > 0]):
            m = (ref.mask == iid) & np.isfinite(noisy.depth) & np.isfinite(ref.depth)
            x, y, z = (ref.nocs[m] - 0.5).T
            a = np.stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], 1)
            e = noisy.depth[m] - ref.depth[m]
            res = e - a @ np.linalg.lstsq(a, e, rcond=None)[0]
            out.append(1 - res.var() / e.var())
        return out

    field = ErrorFamilies(field=0.05, field_cells=(1,), field_drift=0.6)
    got = {}
    for v in ("tuning", "heldout4"):
        clean = world_frames(ErrorFamilies(), 3, 3, v).frames
        got[v] = sum((r2(a, b) for a, b in zip(world_frames(field, 3, 3, v).frames, clean)), [])
    assert min(got["heldout4"]) > 1 - 1e-9 and max(got["tuning"]) < 1 - 1e-5, got
    clean = world_frames(ErrorFamilies(), 4, 3, "heldout4").frames
    scaled = world_frames(ErrorFamilies(depth_scale=0.15), 4, 3, "heldout4").frames
    factors = []
    for a, b in zip(scaled, clean):
        ratio = a.depth / b.depth
        assert np.allclose(ratio[b.mask == 0], ratio[b.mask == 0].flat[0], rtol=1e-12)
        per = [ratio[b.mask == i] for i in np.unique(b.mask[b.mask > 0])]
        assert max(np.ptp(r) for r in per) < 1e-12
        factors.append([r[0] for r in per])
    assert np.ptp(np.array(factors), axis=0).min() > 0  # anew in every frame
    stretched = world_frames("only_nocs_field", 4, 1, "heldout4").frames[0]
    for ob in clean[0].objects:
        m = clean[0].mask == ob.instance_id
        move = stretched.nocs[m] - clean[0].nocs[m]
        u, s, vt = np.linalg.svd(move, full_matrices=False)
        assert s[1] < 1e-6 * s[0]  # one direction: the viewing axis in the object's frame
        view = ob.rotation[2] / np.linalg.norm(ob.rotation[2])  # d depth / d NOCS
        assert abs(abs(vt[0] @ view) - 1) < 1e-9
    quant = world_frames("predicted", 4, 1, "heldout4").frames[0].nocs
    assert np.allclose(quant * 255, np.round(quant * 255), atol=1e-6)


def test_fourth_heldout_model_masks_have_holes_and_its_fine_fields_are_rings():
    """heldout4's masks are polygons with holes (8 frames: 21 instances with a hole, 1 under the
    tuning model's erosion and dilation, where objects overlap), and its finer depth fields are
    radial: the lines along the field's gradient meet in one point (measured 0.07 px rms
    off it; the tuning model's grid field misses the best point by 46 px)."""
    from scipy import ndimage

    from fcop_ros.synthetic.world import (_FIELDS, ErrorFamilies, _grid_field, _ring_field,
                                          world_frame)

    def holes(v):
        n = 0
        for s in range(8):
            mask = world_frame(ErrorFamilies(mask_px=3), s, v).mask
            for iid in np.unique(mask[mask > 0]):
                m = mask == iid
                n += int((ndimage.binary_fill_holes(m) & ~m).any())
        return n
    assert holes("heldout4") >= 10 and holes("tuning") <= 2

    def miss(field):
        gy, gx = np.gradient(field)
        g = np.hypot(gx, gy)
        yy, xx = np.nonzero(g > np.percentile(g, 50))
        ux, uy = gx[yy, xx] / g[yy, xx], gy[yy, xx] / g[yy, xx]
        a = np.stack([uy, -ux], 1)
        b = xx * uy - yy * ux
        c = np.linalg.lstsq(a, b, rcond=None)[0]
        return float(np.sqrt(np.mean((a @ c - b) ** 2)))
    rng = np.random.default_rng(0)
    assert miss(_ring_field(rng, 120, 160, 2)) < 1.0 < 10.0 < miss(_grid_field(rng, 120, 160, 2))
    assert _FIELDS["heldout4"] is _ring_field


def test_fifth_heldout_model_errs_in_tiles_parts_and_hulls():
    """heldout5: its depth field is flat within tiles (most pixels' gradient below 1e-3 of the
    field's std; a grid field's nowhere is), one side of a plane through each object carries
    the whole NOCS displacement (two values per object), and its masks are convex (each
    instance fills its hull; tuning-model masks of the same frames leave concavities)."""
    import cv2

    from fcop_ros.synthetic.world import (_FIELDS, ErrorFamilies, _grid_field, _tile_field,
                                          world_frame)

    rng = np.random.default_rng(0)
    flat = [np.mean(np.hypot(*np.gradient(f(rng, 120, 160, 2))) < 1e-3)
            for f in (_tile_field, _grid_field)]
    assert flat[0] > 0.7 and flat[1] < 0.01, flat
    assert _FIELDS["heldout5"] is _tile_field
    clean = world_frame(ErrorFamilies(), 5, "heldout5")
    shifted = world_frame(ErrorFamilies(nocs_field=0.03), 5, "heldout5")
    for iid in np.unique(clean.mask[clean.mask > 0]):
        move = (shifted.nocs - clean.nocs)[clean.mask == iid]
        assert len(np.unique(np.round(move, 9), axis=0)) <= 3  # 0, the shift, clipped at 0 / 1

    def kept_and_fill(variant):
        kept, fill = [], []
        for seed in range(6):
            truth = world_frame(ErrorFamilies(), seed, variant).mask
            fr = world_frame(ErrorFamilies(mask_px=2), seed, variant)
            for iid in np.unique(fr.mask[fr.mask > 0]):
                m = (fr.mask == iid).astype(np.uint8)
                hull = np.zeros_like(m)
                cv2.fillPoly(hull, [cv2.convexHull(cv2.findNonZero(m))], 1)
                fill.append(m.sum() / hull.sum())
                if (truth == iid).any():
                    kept.append(np.mean(m[truth == iid] > 0))
        return min(kept), np.median(fill)
    # Measured: heldout5 keeps every true pixel (1.0) and fills 0.984 of its hull (the rest:
    # pixels of nearer instances); the tuning model's erosions keep 0.735 of some instance and
    # fill 0.977.
    (k5, f5), (kt, ft) = kept_and_fill("heldout5"), kept_and_fill("tuning")
    assert k5 == 1.0 > 0.9 > kt and f5 > ft, (k5, f5, kt, ft)


def test_sixth_heldout_model_errs_as_a_network_trained_on_other_cameras():
    """heldout6: its coarsest depth field is the squared distance from the image centre (its
    correlation with r^2 is +-1; ten grid fields measured -0.39..0.62), the finer ones are
    constant along each image row, the nearer surface spreads over the farther at depth edges
    (every moved pixel nearer), the NOCS move towards or from each object's centre most at its
    silhouette, and a mask goes through a 28x28 head (measured on 10 instances: area -4.7% to
    +1.7%, 0.6% to 4.7% of the pixels changed)."""
    from fcop_ros.synthetic.world import (_FIELDS, ErrorFamilies, _lens_row_field,
                                          world_frame)

    assert _FIELDS["heldout6"] is _lens_row_field
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:120, 0:160]
    r2 = (yy - 59.5) ** 2 + (xx - 79.5) ** 2
    for _ in range(3):
        c = np.corrcoef(_lens_row_field(rng, 120, 160, 1).ravel(), r2.ravel())[0, 1]
        assert abs(abs(c) - 1.0) < 1e-9, c
    rows = _lens_row_field(rng, 120, 160, 4)
    assert np.ptp(rows, axis=1).max() == 0.0 and np.ptp(rows[:, 0]) > 1.0
    clean = world_frame(ErrorFamilies(), 3, "heldout6")
    fat = world_frame(ErrorFamilies(edge_px=3), 3, "heldout6")
    ok = np.isfinite(clean.depth) & np.isfinite(fat.depth)
    moved = fat.depth[ok] != clean.depth[ok]
    assert moved.any() and np.all(fat.depth[ok][moved] < clean.depth[ok][moved])
    rim = world_frame(ErrorFamilies(nocs_field=0.03), 3, "heldout6")
    import cv2
    for iid in np.unique(clean.mask[clean.mask > 0]):
        m = clean.mask == iid
        if m.sum() < 200:
            continue
        dist = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, 3)[m]
        move = np.linalg.norm((rim.nocs - clean.nocs)[m], axis=1)
        assert move[dist <= 2].mean() > 3 * move[dist >= 10].mean()
    for seed in range(4):
        truth = world_frame(ErrorFamilies(), seed, "heldout6").mask
        head = world_frame(ErrorFamilies(mask_px=2), seed, "heldout6").mask
        for iid in np.unique(truth[truth > 0]):
            t, h = truth == iid, head == iid
            assert abs(h.sum() / t.sum() - 1) < 0.06 and np.sum(t != h) / t.sum() < 0.06


def test_seventh_heldout_model_errs_as_networks_that_read_the_image():
    """heldout7: its coarsest depth field is the image's brightness, albedo times Lambertian
    shading: one value over the table, a plane of one colour (measured ptp 2e-16..4e-14 on 4
    tables, where the tuning grid field spans 0.107..0.149), and on each object a function of
    the surface normal alone (pixels of one normal within 9e-14; each object's error spans
    0.030..0.198); its finer fields are drawn per segment (median step across silhouettes
    0.72..1.07 of the field's std, at most 0.10 between neighbours inside one); each object's
    NOCS move along one direction, the image axis of its box's longer side in the object's
    frame (across the viewing axis), by a factor 3 rms min(1, aspect - 1), one rms per
    sequence (measured within 1e-16 over a frame's objects); an instance's border with the
    background moves one way for a whole sequence (28 instances, 4 frames: 0 changed area both
    ways; the tuning model's, redrawn per frame: 20); and of two touching
    instances one, kept for the sequence, takes a band of the other that flickers from frame
    to frame (6 frames of seed 0: 5..19 and 13..43 pixels), each pixel within px of it and
    given the NOCS of its nearest own pixel."""
    import cv2
    from scipy import ndimage

    from fcop_ros.synthetic.world import (ErrorFamilies, ErrorState, _bleed, _normals,
                                          world_frame, world_frames)

    coarse = ErrorFamilies(field=0.05, field_cells=(1,), field_drift=0.6)
    for seed in range(4):
        spans = {}
        for v in ("tuning", "heldout7"):
            clean = world_frame(ErrorFamilies(), seed, v)
            rel = world_frame(coarse, seed, v).depth / clean.depth - 1
            table = (clean.mask == 0) & np.isfinite(clean.depth)
            table = cv2.erode(table.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            spans[v] = np.ptp(rel[table])
        assert spans["heldout7"] < 1e-12 and spans["tuning"] > 0.05, spans
        n = _normals(clean)  # heldout7's frame
        for iid in np.unique(clean.mask[clean.mask > 0]):
            m = (clean.mask == iid) & np.all(np.isfinite(n), -1)
            _, group = np.unique(np.round(n[m], 9), axis=0, return_inverse=True)
            err = rel[m]
            order = np.argsort(group.ravel(), kind="stable")
            same = np.diff(group.ravel()[order]) == 0
            pd = np.abs(np.diff(err[order]))[same]
            assert np.ptp(err) > 0.02 and (pd.size == 0 or pd.max() < 1e-12), (iid, pd.max())

    rng = np.random.default_rng(0)
    for seed in range(4):
        clean = world_frame(ErrorFamilies(), seed, "heldout7")
        g = ErrorState.start(ErrorFamilies(field_drift=0.6), rng, "heldout7")._segments(
            rng, clean, 4)
        step = np.abs(np.diff(g, axis=1))
        inside = np.diff(clean.mask.astype(int), axis=1) == 0
        assert np.median(step[~inside]) > 5 * step[inside].max()

    for seed in range(4):
        clean = world_frame(ErrorFamilies(), seed, "heldout7")
        moved = world_frame(ErrorFamilies(nocs_field=0.03), seed, "heldout7")
        per_aspect = []
        for ob in clean.objects:
            m = clean.mask == ob.instance_id
            if m.sum() < 100:
                continue
            move = (moved.nocs - clean.nocs)[m]
            if not move.any():  # a square box: no stretch
                continue
            ys, xs = np.nonzero(m)
            axis = ob.rotation[0 if np.ptp(xs) >= np.ptp(ys) else 1]  # image axis, object frame
            q = (clean.nocs[m] - clean.nocs[m].mean(0)) @ axis
            factor = np.median((move @ axis)[abs(q) > 0.05] / q[abs(q) > 0.05])
            long, short = sorted((np.ptp(xs) + 1, np.ptp(ys) + 1), reverse=True)
            assert np.abs(move - np.outer(move @ axis, axis)).max() < 1e-12
            per_aspect.append(abs(factor) / min(1.0, long / short - 1.0))
        # One strength per sequence (drawn up to the bound 0.03: 3 x 0.03 per unit aspect).
        assert np.ptp(per_aspect) < 1e-9 and 0 < per_aspect[0] <= 0.09, per_aspect

    both_ways = {}
    for v in ("heldout7", "tuning"):
        both_ways[v] = 0
        for seed in range(8):
            truth = world_frames(ErrorFamilies(), seed, 4, v).frames
            masked = world_frames(ErrorFamilies(mask_px=3), seed, 4, v).frames
            for iid in np.unique(truth[0].mask[truth[0].mask > 0]):
                signs = {np.sign(np.sum(a.mask == iid) - np.sum(t.mask == iid))
                         for a, t in zip(masked, truth)}
                both_ways[v] += len(signs - {0}) > 1
    assert both_ways["heldout7"] == 0 and both_ways["tuning"] >= 10, both_ways

    clean = world_frame(ErrorFamilies(), 0, "heldout7")  # instances 2-3 and 1-4 touch
    rng = np.random.default_rng(1)
    state = ErrorState.start(ErrorFamilies(), rng, "heldout7")
    winners, sizes = {}, {}
    for _ in range(6):
        new, nocs = _bleed(clean.mask, clean.mask.copy(), clean.nocs.copy(), 3, state, rng)
        taken = new != clean.mask
        for a, b in set(zip(new[taken].tolist(), clean.mask[taken].tolist())):
            winners.setdefault(frozenset((a, b)), set()).add(a)
            sizes.setdefault(a, []).append(int(np.sum(taken & (new == a))))
            dist, (iy, ix) = ndimage.distance_transform_edt(clean.mask != a,
                                                            return_indices=True)
            t = taken & (new == a)
            assert dist[t].max() <= 3
            np.testing.assert_array_equal(nocs[t], clean.nocs[iy[t], ix[t]])
    assert len(winners) == 2 and all(len(w) == 1 for w in winners.values()), winners
    assert all(len(set(s)) > 1 for s in sizes.values()), sizes


def test_eighth_heldout_model_errs_through_priors_and_pipes():
    """heldout8: its coarsest depth field is the familiar-size cue, one relative error over each
    object, proportional to -ln(size / 0.17) by one reliance kept for the sequence (measured,
    10 objects of 4 seeds, 3 frames each: ptp within an object 4e-16, between frames 1e-16, of
    the ratio to the log size 6e-16), none on the table (where the tuning grid field spans
    0.107..0.149); its finer fields are image fields times the true depth over the objects'
    median true depth, up to 3; with per-pixel depth noise the inverse depth lies on 256 evenly
    spaced levels between its extremes (within 2e-13 of a level, the tuning model's up to 0.5
    off; the terraces alone err 0.0005 rms on the objects); each object's NOCS are turned
    about the vertical axis of its main part by k sin(azimuth from the viewing direction) (on
    11 cans, bowls and bottles of 8 seeds: height and distance from the axis kept within 1e-16,
    k one value per object within 3e-14, |k| 0.019..0.054 <= 2 nocs_field); with per-pixel
    NOCS noise the NOCS image is the JPEG of the 8-bit one at a quality in 80..95 (exactly, on
    the objects), its error jumping across the 8x8 block seams (ratio of steps across them to
    steps within them 1.23..1.53 on 4 seeds, heldout4's 8-bit rounding alone 0.99..1.02); and
    each instance's mask is its true one grown by 0..px and cut by a box within px of the true
    box (54 of 60 instances of 16 seeds cut, each exactly the grown mask within its own box;
    in the world's frames, 32 of 39 instances standing apart cut, each so)."""
    from fcop_ros.synthetic.render import _NORMALISED
    from fcop_ros.synthetic.world import (ErrorFamilies, ErrorState, _boxed, _jpeg,
                                          world_frame, world_frames)

    coarse = ErrorFamilies(field=0.05, field_cells=(1,), field_drift=0.6)
    for seed in range(4):
        frames = world_frames(coarse, seed, 3, "heldout8").frames
        truth = world_frames(ErrorFamilies(), seed, 3, "heldout8").frames
        size = {o.instance_id: o.scale for o in truth[0].objects}
        per_frame = []
        for fr, clean in zip(frames, truth):
            rel = fr.depth / clean.depth - 1
            table = (clean.mask == 0) & np.isfinite(clean.depth)
            assert np.abs(rel[table]).max() < 1e-12
            value = {}
            for iid in np.unique(clean.mask[clean.mask > 0]):
                err = rel[clean.mask == iid]
                assert np.ptp(err) < 1e-12
                value[int(iid)] = err[0]
            per_frame.append(value)
            ratio = [value[i] / np.log(size[i] / 0.17) for i in value]
            assert np.ptp(ratio) < 1e-9 and ratio[0] < 0, ratio
        for i in per_frame[0]:  # one error per object for the sequence
            assert np.ptp([v[i] for v in per_frame if i in v]) < 1e-12
    clean = world_frame(ErrorFamilies(), 0, "tuning")
    rel = world_frame(coarse, 0, "tuning").depth / clean.depth - 1
    assert np.ptp(rel[(clean.mask == 0) & np.isfinite(clean.depth)]) > 0.05

    for seed in range(4):
        clean = world_frame(ErrorFamilies(), seed, "heldout8")
        h, w = clean.mask.shape
        grown = ErrorState.start(ErrorFamilies(field_drift=0.6), np.random.default_rng(1),
                                 "heldout8")._grown(np.random.default_rng(2), clean, 2)
        base = ErrorState.start(ErrorFamilies(field_drift=0.6), np.random.default_rng(1),
                                "heldout8")._field(("depth", 2), np.random.default_rng(2), h, w, 2)
        ok = np.isfinite(clean.depth) & (np.abs(base) > 1e-3)
        ref = np.median(clean.depth[np.isfinite(clean.depth) & (clean.mask > 0)])
        np.testing.assert_allclose(grown[ok] / base[ok],
                                   np.minimum(clean.depth[ok] / ref, 3.0), rtol=1e-9)
        assert np.ptp(clean.depth[ok] / ref) > 0.2

    for v in ("heldout8", "tuning"):
        fr = world_frame(ErrorFamilies(depth_pixel=0.005), 1, v)
        inv = 1.0 / fr.depth[np.isfinite(fr.depth)]
        level = (inv - inv.min()) / ((inv.max() - inv.min()) / 255.0)
        off = np.abs(level - np.round(level)).max()
        assert (off < 1e-6) == (v == "heldout8"), (v, off)

    axis = {c: (0.5 + _NORMALISED[c][0][0][1][0], 0.5 + _NORMALISED[c][0][0][1][2])
            for c in ("can", "bowl", "bottle")}
    checked = 0
    for seed in range(8):
        clean = world_frame(ErrorFamilies(), seed, "heldout8")
        moved = world_frame(ErrorFamilies(nocs_field=0.03), seed, "heldout8")
        for ob in clean.objects:
            m = clean.mask == ob.instance_id
            if ob.category not in axis or m.sum() < 100:
                continue
            ax, az = axis[ob.category]
            a, b = clean.nocs[m], moved.nocs[m]
            np.testing.assert_allclose(b[:, 1], a[:, 1], atol=1e-12)
            np.testing.assert_allclose(np.hypot(b[:, 0] - ax, b[:, 2] - az),
                                       np.hypot(a[:, 0] - ax, a[:, 2] - az), atol=1e-12)
            view = ob.rotation.T @ -np.asarray(ob.translation)
            seen = np.arctan2(view[2], view[0])
            phi = [np.angle(np.exp(1j * (np.arctan2(q[:, 2] - az, q[:, 0] - ax) - seen)))
                   for q in (a, b)]
            big = np.abs(np.sin(phi[0])) > 0.2
            k = np.angle(np.exp(1j * (phi[1] - phi[0])))[big] / np.sin(phi[0][big])
            assert np.ptp(k) < 1e-9 and 0 < abs(k[0]) <= 0.06 + 1e-12, k
            checked += 1
    assert checked >= 5

    ratios = {}
    for v in ("heldout8", "heldout4"):
        ratios[v] = []
        for seed in range(4):
            clean = world_frame(ErrorFamilies(), seed, v)
            fr = world_frame(ErrorFamilies(nocs_pixel=1e-9), seed, v)
            obj = fr.mask > 0
            assert np.abs(fr.nocs * 255 - np.round(fr.nocs * 255)).max() < 1e-9
            if v == "heldout8":
                assert any(np.array_equal(fr.nocs[obj], _jpeg(clean.nocs, q)[obj])
                           for q in range(80, 96))
            err = np.abs(np.diff(fr.nocs - clean.nocs, axis=1)).sum(-1)
            inner = (cv2_erode(obj, 9))[:, 1:] & (cv2_erode(obj, 9))[:, :-1]
            seam = (np.arange(err.shape[1]) % 8 == 7)[None, :] & inner
            ratios[v].append(err[seam].mean() / err[inner & ~seam].mean())
    assert min(ratios["heldout8"]) > 1.15 and max(ratios["heldout4"]) < 1.08, ratios

    rng = np.random.default_rng(0)
    cut = total = 0
    for seed in range(16):
        truth = world_frame(ErrorFamilies(), seed, "heldout8").mask
        for iid in np.unique(truth[truth > 0]):
            t = truth == iid
            new = _boxed(t, 3, rng).astype(bool)
            ys, xs = np.nonzero(new)
            box = np.zeros_like(t)
            box[ys.min():ys.max() + 1, xs.min():xs.max() + 1] = True
            assert any(np.array_equal(new, cv2_dilate(t, r) & box) for r in range(4))
            ty, tx = np.nonzero(t)
            assert max(abs(ys.min() - ty.min()), abs(ys.max() - ty.max()),
                       abs(xs.min() - tx.min()), abs(xs.max() - tx.max())) <= 3
            cut += bool(np.any(t & ~new))
            total += 1
    assert 0.2 * total < cut < total, (cut, total)
    cut = total = 0
    for seed in range(16):  # and so the world's masks, where an instance stands apart
        truth = world_frame(ErrorFamilies(), seed, "heldout8").mask
        masked = world_frame(ErrorFamilies(mask_px=3), seed, "heldout8").mask
        for iid in np.unique(truth[truth > 0]):
            t, new = truth == iid, masked == iid
            if np.any(cv2_dilate(t, 7) & (truth > 0) & ~t) or not new.any():
                continue
            ys, xs = np.nonzero(new)
            box = np.zeros_like(t)
            box[ys.min():ys.max() + 1, xs.min():xs.max() + 1] = True
            assert any(np.array_equal(new, cv2_dilate(t, r) & box) for r in range(4)), seed
            cut += bool(np.any(t & ~new))
            total += 1
    assert cut >= 3 and total >= 10, (cut, total)


def cv2_erode(m, k):
    import cv2

    return cv2.erode(m.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)


def cv2_dilate(m, r):
    import cv2

    return cv2.dilate(m.astype(np.uint8), np.ones((2 * r + 1,) * 2, np.uint8)).astype(bool)


def test_a_jpeg_nocs_image_errs_in_chroma_at_the_silhouettes_and_in_no_preset():
    """The opt-in ``nocs_jpeg`` family (ROS's compressed transport on the NOCS image): depth and
    mask untouched; the NOCS error is mostly chroma (JPEG halves the colour resolution and
    quantises it coarsely) and mostly within 3 px of the silhouettes. Measured on seeds 0-9: rim
    chroma 0.039-0.047 rms, rim luma 0.007-0.025, inner chroma 0.006-0.012. No preset but the
    ones named for it turns it on, so no tuning frame changed when it came."""
    from fcop_ros.synthetic.world import PIPE_FAMILIES, WORLD_PRESETS, ErrorFamilies, world_frame

    ycc = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5],
                    [0.5, -0.418688, -0.081312]])
    for seed in range(10):
        clean = world_frame(ErrorFamilies(), seed)
        sent = world_frame("only_nocs_jpeg", seed)
        assert np.array_equal(clean.mask, sent.mask)
        assert np.array_equal(clean.depth, sent.depth, equal_nan=True)
        on = clean.mask > 0
        inner = cv2_erode(on, 7)
        rim = on & ~inner
        e = (sent.nocs - clean.nocs) @ ycc.T

        def rms(m, c):
            return float(np.sqrt(np.mean(np.sum(e[m][:, c] ** 2, axis=-1))))

        assert rms(rim, [1, 2]) > 1.5 * rms(rim, [0]), seed
        assert rms(rim, [1, 2]) > 3 * rms(inner, [1, 2]), seed
        assert 0.02 < rms(rim, [1, 2]) < 0.08, seed
    assert PIPE_FAMILIES == ("nocs_jpeg",)
    on_presets = {k for k, v in WORLD_PRESETS.items() if v.nocs_jpeg}
    assert on_presets == {"only_nocs_jpeg", "predicted_nocs_jpeg"}
    assert WORLD_PRESETS["predicted_nocs_jpeg"] == replace(WORLD_PRESETS["predicted"],
                                                           nocs_jpeg=True)


def test_ninth_heldout_model_errs_as_the_pipeline_around_the_networks():
    """heldout9: its depth fields are fixed in the scene, an error in metres that a surface
    point keeps as the camera moves (the same points' errors in frames 0 and 10 of 4 seeds,
    matched within 0.5 mm in the first frame's camera coordinates, differ by 0.002-0.015 of
    their rms; the tuning grid field, kept in the image with field_drift 0, by 0.61-1.04);
    with per-pixel depth noise the depth is the truth area-averaged to 1/2 or 1/4 of the
    size, one factor for the sequence, and brought back bilinearly (a ramp kept within 1e-12, a
    step spread over k..2k pixels; in the world's frames 0.004-0.016 rms relative error on the
    objects, from their silhouettes, median 4e-6..1e-4); each object's NOCS move by c (their
    affine fit in the image - the NOCS), one c per object within 1e-9, 0 < |c| <= 3
    nocs_field, both signs, the move without an affine part (0.0025 rms per axis, the range
    test's); with per-pixel NOCS noise each frame's NOCS and mask are the last frame's truth
    and its depth its own (0.025-0.029 rms per axis where the masks agree, 0.4-2.3% of the
    pixels relabelled, seeds 0-3), and never without; with mask errors the images are moved by
    whole pixels, up to 1% of the image's size per axis at mask_px 3 (10 of 12 seeds moved, by
    1-2 px, up to 0.83%; 0.006-0.032 rms relative depth error on the true objects' pixels),
    the same in every frame, and the frame's principal point is the one under which the
    pixels obey the camera model exactly."""
    from scipy.spatial import cKDTree

    from fcop_ros.synthetic.world import ErrorFamilies, _low_res, world_frames

    def scene_points(fr, first):
        h, w = fr.depth.shape
        cx, cy = fr.principal_point
        vv, uu = np.mgrid[0:h, 0:w]
        ok = np.isfinite(fr.depth)
        z = fr.depth[ok]
        x = np.stack([z * (uu[ok] - cx) / fr.focal, z * (vv[ok] - cy) / fr.focal, z], -1)
        a = min(first.objects, key=lambda o: o.instance_id)
        b = {o.instance_id: o for o in fr.objects}[a.instance_id]
        return ok, (x - b.translation) @ (a.rotation @ b.rotation.T).T + a.translation

    still = {}
    for v in ("heldout9", "tuning"):
        still[v] = []
        fam = ErrorFamilies(field=0.05, field_cells=(1, 2, 4), field_drift=0.0)
        for seed in range(4):
            truth = world_frames(ErrorFamilies(), seed, 11, v).frames
            seen = world_frames(fam, seed, 11, v).frames
            err = [seen[k].depth - truth[k].depth for k in (0, 10)]
            (ok0, p0), (ok1, p1) = (scene_points(truth[k], truth[0]) for k in (0, 10))
            dist, idx = cKDTree(p0).query(p1)
            near = dist < 5e-4
            assert near.sum() > 1000, near.sum()
            e0, e1 = err[0][ok0][idx[near]], err[1][ok1][near]
            still[v].append(np.sqrt(np.mean((e1 - e0) ** 2) / np.mean(e0 ** 2)))
    assert max(still["heldout9"]) < 0.05 and min(still["tuning"]) > 0.3, still

    ramp = np.tile(np.linspace(1.0, 2.0, 64), (48, 1))
    step = np.where(np.arange(64) < 30, 1.0, 2.0) * np.ones((48, 1))
    for k in (2, 4):
        np.testing.assert_allclose(_low_res(ramp, k)[:, 2 * k:-2 * k],
                                   ramp[:, 2 * k:-2 * k], atol=1e-12)
        moved = np.abs(_low_res(step, k) - step) > 1e-9
        assert (moved.sum(1) >= k).all() and (moved.sum(1) <= 2 * k).all(), k
    for v in ("heldout9", "tuning"):
        for seed in range(4):
            truth = world_frames(ErrorFamilies(), seed, 2, v).frames
            seen = world_frames(ErrorFamilies(depth_pixel=1e-12), seed, 2, v).frames
            same = [[np.allclose(s.depth, _low_res(t.depth, k), rtol=1e-9, equal_nan=True)
                     for k in (2, 4)] for s, t in zip(seen, truth)]
            if v == "heldout9":  # one factor, kept for the sequence
                assert same[0] == same[1] and sum(same[0]) == 1, (seed, same)
            else:
                assert not any(same[0] + same[1]), (seed, same)

    signs = set()
    for seed in range(8):
        truth = world_frames(ErrorFamilies(), seed, 2, "heldout9").frames
        seen = world_frames(ErrorFamilies(nocs_field=0.03), seed, 2, "heldout9").frames
        for t, s in zip(truth, seen):
            np.testing.assert_array_equal(s.mask, t.mask)
            for iid in np.unique(t.mask[t.mask > 0]):
                m = t.mask == iid
                if m.sum() < 200:
                    continue
                ys, xs = np.nonzero(m)
                a = np.column_stack([np.ones(len(ys)), xs, ys])
                q = t.nocs[m]
                resid = q - a @ np.linalg.lstsq(a, q, rcond=None)[0]
                move = s.nocs[m] - q
                inside = ((s.nocs[m] > 0) & (s.nocs[m] < 1)).all(1)
                big = inside[:, None] & (np.abs(resid) > 1e-3)
                c = move[big] / resid[big]
                assert np.ptp(c) < 1e-9 and 0 < abs(c[0]) <= 0.09 + 1e-12, (seed, iid)
                signs.add(np.sign(c[0]))
                affine = np.linalg.lstsq(a[inside], move[inside], rcond=None)[0]
                assert np.abs(affine).max() < 1e-9 * max(1.0, np.abs(move).max())
    assert signs == {-1.0, 1.0}, signs

    for seed in range(4):
        truth = world_frames(ErrorFamilies(), seed, 3, "heldout9").frames
        late = world_frames(ErrorFamilies(nocs_pixel=1e-9), seed, 3, "heldout9").frames
        for k, fr in enumerate(late):
            src = truth[max(k - 1, 0)]
            np.testing.assert_array_equal(fr.mask, src.mask)
            np.testing.assert_allclose(fr.nocs, src.nocs, atol=1e-7)
            np.testing.assert_array_equal(fr.depth, truth[k].depth)
        assert np.any(truth[1].mask != truth[0].mask)
        for k, fr in enumerate(world_frames(ErrorFamilies(), seed, 3, "heldout9").frames):
            np.testing.assert_array_equal(fr.mask, truth[k].mask)

    moved = []
    for seed in range(12):
        truth = world_frames(ErrorFamilies(), seed, 2, "heldout9").frames
        seen = world_frames(ErrorFamilies(mask_px=3), seed, 2, "heldout9").frames
        h, w = truth[0].mask.shape
        shifts = []
        for t, s in zip(truth, seen):
            dx = s.principal_point[0] - t.principal_point[0]
            dy = s.principal_point[1] - t.principal_point[1]
            assert dx == int(dx) and dy == int(dy)
            assert abs(dx) <= round(0.01 * w) and abs(dy) <= round(0.01 * h), (dx, dy, w, h)
            dx, dy = int(dx), int(dy)
            ys, xs = slice(max(dy, 0), h + min(dy, 0)), slice(max(dx, 0), w + min(dx, 0))
            np.testing.assert_array_equal(
                s.depth[ys, xs], t.depth[max(-dy, 0):h - max(dy, 0), max(-dx, 0):w - max(dx, 0)])
            assert np.isnan(s.depth).sum() - np.isnan(t.depth[ys, xs]).sum() == (
                h * w - (h - abs(dy)) * (w - abs(dx)))
            # The rendered pixels obey the camera model under the frame's principal point.
            cx, cy = s.principal_point
            label = np.zeros_like(t.mask)  # the true mask, moved with the images
            label[ys, xs] = t.mask[max(-dy, 0):h - max(dy, 0), max(-dx, 0):w - max(dx, 0)]
            inner = (s.mask == label) & (label > 0)
            v, u = np.nonzero(inner)
            d = s.depth[v, u]
            x = np.column_stack([d * (u - cx) / s.focal, d * (v - cy) / s.focal, d])
            pose = {o.instance_id: o for o in s.objects}
            for iid in np.unique(s.mask[inner]):
                o, sel = pose[int(iid)], s.mask[v, u] == iid
                pred = o.scale * (s.nocs[v[sel], u[sel]] - 0.5) @ o.rotation.T + o.translation
                assert np.abs(pred - x[sel]).max() < 1e-9
            shifts.append((dx, dy))
        assert shifts[0] == shifts[1]
        moved.append(shifts[0] != (0, 0))
    assert 6 <= sum(moved) < 12, moved
    for v, fam in (("tuning", ErrorFamilies(mask_px=3)), ("heldout9", ErrorFamilies())):
        fr, clean = (world_frames(f, 0, 1, v).frames[0] for f in (fam, ErrorFamilies()))
        assert fr.principal_point == clean.principal_point


def test_the_tuning_world_s_principal_point_leaves_the_centre_and_nothing_else_moves():
    """`sensor` and `predicted` sequences are seen through a camera whose principal point lies
    up to 2% of the image off its centre (measured over seeds 0-199: largest 1.9%, rms 0.70%
    per axis), kept for the sequence and recorded in the frames; drawn from a generator of its
    own, so the other families' strengths are those drawn without it, and only in the tuning
    model."""
    from dataclasses import replace

    from fcop_ros.synthetic.world import WORLD_PRESETS, world_frames

    offsets = []
    for s in range(200):
        seq = world_frames("sensor", s, 2)
        w, h = seq.size
        pp = [fr.principal_point for fr in seq.frames]
        assert pp[0] == pp[1]
        offsets.append((np.array(pp[0]) - [(w - 1) / 2, (h - 1) / 2]) / [w, h])
        if s < 5:
            centred = world_frames(replace(WORLD_PRESETS["sensor"], principal_point=0.0), s, 1)
            assert replace(seq.errors, principal_point=0.0) == centred.errors
            held = world_frames("sensor", s, 1, variant="heldout2").frames[0]
            assert held.principal_point == ((w - 1) / 2, (h - 1) / 2)
    off = np.abs(np.array(offsets))
    assert off.max() <= 0.02 and 0.005 < np.sqrt(np.mean(off ** 2)) < 0.008
    assert world_frames("only_principal_point", 0, 1).errors.principal_point == 0.02


def _held_out(variant, fam, seed, n=2, **kw):
    """The error model ``variant``'s truth (frames of ``seed``) and what it makes of them under
    the strengths ``fam`` as they are (not drawn), with the state that kept its errors."""
    from fcop_ros.synthetic.world import ErrorFamilies, ErrorState, apply_errors, world_frames

    truth = world_frames(ErrorFamilies(), seed, n, variant, **kw).frames
    rng = np.random.default_rng(seed)
    state = ErrorState.start(fam, rng, variant)
    return truth, [apply_errors(t, state, rng) for t in truth], state


def _objects_of_kept_masks(variant, fam, seeds):
    """Each true object of the frames of ``seeds`` under the error model ``variant`` at the
    strengths ``fam``, whose masks it keeps (checked): (seed, the truth's frame, the frame seen,
    the error state, the instance id, its mask)."""
    for seed in seeds:
        truth, seen, state = _held_out(variant, fam, seed)
        for t, s in zip(truth, seen):
            np.testing.assert_array_equal(s.mask, t.mask)
            for iid in np.unique(t.mask[t.mask > 0]):
                yield seed, t, s, state, iid, t.mask == iid


def _true_ids(seen, truth):
    """Each instance id of ``seen`` and the true instance of which it covers the largest share
    (0 where under half of its pixels show an object: a spurious blob)."""
    area = np.bincount(truth.mask.ravel()).astype(float)
    out = {}
    for i in np.unique(seen.mask[seen.mask > 0]):
        count = np.bincount(truth.mask[seen.mask == i], minlength=len(area))
        share = np.where(area > 0, count / np.maximum(area, 1), 0.0)
        share[0] = 0.0
        out[int(i)] = int(share.argmax()) if count[1:].sum() >= count.sum() / 2 else 0
    return out


def _lens_fit(seen, truth):
    """Where the points the NOCS of ``seen`` name (posed as the objects truly are) fall in its
    pixels, well inside each instance: a least-squares camera with a principal point (cx, cy)
    and radial distortion k1 (1 - r^2 / 4) r^2, against a pinhole centred on (cx, cy).
    Fitted on the pixels whose depth is their point's within 1e-9 (not a dilated mask's band of
    another surface). Returns cx, cy, k1, the 99th percentile of the residuals (px) of the two,
    the largest of the first, and the share of the pixels well inside that were left out."""
    import cv2

    pose = {o.instance_id: o for o in truth.objects}
    rows, rhs, out = [], [], []
    for iid, tid in _true_ids(seen, truth).items():
        inner = cv2.erode((seen.mask == iid).astype(np.uint8), np.ones((11, 11), np.uint8))
        v, u = np.nonzero(inner)
        if len(v) < 20 or tid not in pose:  # too small, or a spurious blob
            continue
        o = pose[tid]
        x = o.scale * (seen.nocs[v, u] - 0.5) @ o.rotation.T + o.translation
        ok = np.abs(seen.depth[v, u] / x[:, 2] - 1) < 1e-9
        out.append(~ok)
        v, u, x = v[ok], u[ok], x[ok]
        xn, yn = x[:, 0] / x[:, 2], x[:, 1] / x[:, 2]
        r2 = xn * xn + yn * yn
        bend = r2 - r2 * r2 / 4
        one, zero = np.ones_like(xn), np.zeros_like(xn)
        rows += [np.column_stack([one, zero, seen.focal * xn * bend]),
                 np.column_stack([zero, one, seen.focal * yn * bend])]
        rhs += [u - seen.focal * xn, v - seen.focal * yn]
    a, b = np.concatenate(rows), np.concatenate(rhs)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    flat = np.linalg.lstsq(a[:, :2], b, rcond=None)[0]
    resid = np.abs(a @ sol - b)
    return (*sol, np.percentile(resid, 99), np.percentile(np.abs(a[:, :2] @ flat - b), 99),
            resid.max(), np.concatenate(out).mean())


def test_tenth_heldout_model_takes_its_images_through_a_distorting_lens():
    """heldout10, with mask errors (mask_px 3): the depth, NOCS and masks are what a lens with
    radial distortion k1 (r^2 - r^4 / 4) takes, k1 within +-0.02, both signs, kept for the
    sequence (k1 fitted in frames 0 and 1 of 8 seeds within 0.005; the distortion, relative to
    the true focal length, moves the objects' pixels by 0.02-0.3 px against a pinhole's best
    fit, more where the view is wide): the points the NOCS name fall on their pixels through
    it, 99% within 0.05 px (measured 0.016-0.022; bilinear within a surface) and all within
    0.75 (the nearest pixel where a point's four are not one surface), each pixel's depth is
    its point's (but for under 0.5% of the pixels, measured 0-0.1%, which a dilated mask took
    from another surface), and no distortion without mask errors."""
    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    k1s, gain = [], []
    for seed in range(8):
        truth, seen, _ = _held_out("heldout10", ErrorFamilies(mask_px=3), seed)
        fits = [_lens_fit(s, t) for s, t in zip(seen, truth)]
        for cx, cy, k1, resid, pinhole, worst, left in fits:
            assert resid < 0.05 and worst < 0.75 and left < 0.005, (seed, fits)
            assert abs(k1) <= 0.02 + 1e-3, (seed, fits)
        assert abs(fits[0][2] - fits[1][2]) < 5e-3, (seed, fits)
        k1s.append(fits[0][2])
        gain.append(fits[0][4] / fits[0][3])
    assert min(k1s) < -0.005 and max(k1s) > 0.005 and max(gain) > 5, (k1s, gain)
    for seed in range(3):
        truth = world_frames(ErrorFamilies(), seed, 1, "heldout10").frames[0]
        fr = world_frames(ErrorFamilies(blobs=2), seed, 1, "heldout10").frames[0]
        cx, cy, k1, *_ = _lens_fit(fr, truth)
        assert abs(k1) < 1e-3 and (cx, cy) == pytest.approx(truth.principal_point, abs=0.05)
        np.testing.assert_array_equal(fr.depth, truth.depth)


def test_tenth_heldout_model_moves_the_principal_point_by_a_gaussian():
    """heldout10, with mask errors (mask_px 3): the principal point is off the image centre
    by a Gaussian of 0.6% of the image's size per axis (over 40 sequences the shifts over that
    have mean 0.07 and std 0.98, the largest 2.4: a Gaussian's tails, not a uniform's),
    sub-pixel, the same in every frame of a sequence, and the frame's principal point is
    where the pixels say it is (within 0.05 px; measured within 0.01)."""
    from fcop_ros.synthetic.world import ErrorFamilies

    z = []
    for seed in range(40):
        truth, seen, _ = _held_out("heldout10", ErrorFamilies(mask_px=3), seed)
        h, w = truth[0].mask.shape
        shift = [np.subtract(s.principal_point, t.principal_point) for s, t in zip(seen, truth)]
        np.testing.assert_array_equal(shift[0], shift[1])
        assert np.all(shift[0] != np.round(shift[0])), shift[0]
        z.extend(shift[0] / (0.006 * np.array([w, h])))
        if seed < 4:
            cx, cy, *_ = _lens_fit(seen[0], truth[0])
            assert (cx, cy) == pytest.approx(seen[0].principal_point, abs=0.05), seed
    z = np.array(z)
    assert abs(z.mean()) < 0.35 and 0.75 < z.std() < 1.3 and np.abs(z).max() > 1.8, (
        z.mean(), z.std(), np.abs(z).max())


def _detail(depth, m):
    """``depth`` on the pixels ``m`` less its Gaussian blur over them (sigma a third of their
    radius, the blur normalised by ``m``)."""
    import cv2

    sigma = max(np.sqrt(m.sum() / np.pi) / 3.0, 0.5)
    num = cv2.GaussianBlur(np.where(m, depth, 0.0), (0, 0), sigma)
    den = cv2.GaussianBlur(m.astype(np.float64), (0, 0), sigma)
    return depth[m] - num[m] / den[m]


def test_tenth_heldout_model_sharpens_or_flattens_each_objects_relief():
    """heldout10, with relief errors (relief 0.04): each object's depth is its relief error's
    (affine in the true depth) plus a times that of the true depth's detail, the true depth less
    its blur over the object (sigma a third of its radius): exactly (within 1e-9 m), a per
    object within +-3 relief, both signs, kept for the sequence while the relief error drifts
    (measured over 8 seeds: |a| 0.0015-0.11, 14 of each sign; residuals 6e-15 m); the tuning
    model has no such term."""
    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    gains = {}
    for seed in range(8):
        for v in ("heldout10", "tuning"):
            truth = world_frames(ErrorFamilies(), seed, 2, v).frames
            seen = world_frames(ErrorFamilies(relief=0.04), seed, 2, v).frames
            for k, (t, s) in enumerate(zip(truth, seen)):
                for iid in np.unique(t.mask[t.mask > 0]):
                    m = (t.mask == iid) & np.isfinite(t.depth)
                    if m.sum() < 50:
                        continue
                    a = np.column_stack([np.ones(m.sum()), t.depth[m], _detail(t.depth, m)])
                    c, *_ = np.linalg.lstsq(a, s.depth[m], rcond=None)
                    assert np.abs(a @ c - s.depth[m]).max() < 1e-9, (v, seed, iid)
                    gains.setdefault((v, seed, int(iid)), []).append(c[2] / c[1])
    for (v, *_), g in gains.items():
        if v == "tuning":
            assert abs(g[0]) < 1e-9, g
        else:
            assert abs(g[0]) <= 0.12 + 1e-9 and (len(g) < 2 or abs(g[1] - g[0]) < 1e-9), g
    ours = [g[0] for (v, *_), g in gains.items() if v == "heldout10"]
    assert min(ours) < -0.01 and max(ours) > 0.01, ours


def test_tenth_heldout_model_has_holes_in_its_objects_depth():
    """heldout10, with per-pixel depth noise: each object's depth has one to three compact
    holes (NaN; at most 4 connected pieces, an ellipse cut by the object's outline), together
    at most 10% of its pixels (measured over 8 seeds: 0-9.9%, none on 4 of 56 objects' frames),
    drawn anew in every frame (the same object's holes in frames 0 and 1 overlap by 0.04 of
    their union on average, 0.53 at most; kept, they would by nearly all of it), none off the
    objects and none without depth noise; elsewhere the depth is the truth's."""
    import cv2

    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    shares, overlap = [], []
    for seed in range(8):
        truth, seen, _ = _held_out("heldout10", ErrorFamilies(depth_pixel=1e-12), seed)
        holes = [np.isnan(s.depth) & np.isfinite(t.depth) for s, t in zip(seen, truth)]
        for t, s, hole in zip(truth, seen, holes):
            assert not np.any(hole & (t.mask == 0))
            np.testing.assert_allclose(s.depth[~hole], t.depth[~hole], rtol=1e-9)
            for iid in np.unique(t.mask[t.mask > 0]):
                m = t.mask == iid
                shares.append(hole[m].mean())
                assert cv2.connectedComponents((hole & m).astype(np.uint8))[0] - 1 <= 4
        for iid in np.unique(truth[0].mask[truth[0].mask > 0]):
            a, b = (h & (t.mask == iid) for h, t in zip(holes, truth))
            if a.any() and b.any():
                overlap.append((a & b).sum() / (a | b).sum())
        plain = world_frames(ErrorFamilies(nocs_pixel=0.01), seed, 2, "heldout10").frames
        for t, s in zip(truth, plain):
            np.testing.assert_array_equal(np.isnan(s.depth), np.isnan(t.depth))
    assert np.mean(overlap) < 0.15, overlap
    shares = np.array(shares)
    assert shares.max() <= 0.1 and np.mean(shares > 0) > 0.8 and shares.max() > 0.05, shares


def test_tenth_heldout_model_bends_and_tapers_each_objects_nocs():
    """heldout10, with NOCS field errors (nocs_field 0.03): each object's NOCS, q about 0.5, move
    by exactly (within 1e-12) b q_y^2 + c q_y q_x along x, c q_y q_z along z and not along y (a
    bend along its up axis and a taper), b within +-12 and c within +-6 nocs_field, both
    signs of each, kept for the sequence (measured over 8 seeds: |b| 0.009-0.356, |c|
    0.004-0.180); the masks are the truth's."""
    from fcop_ros.synthetic.world import ErrorFamilies

    coef = {}
    for seed, t, s, _, iid, m in _objects_of_kept_masks(
            "heldout10", ErrorFamilies(nocs_field=0.03), range(8)):
        inside = ((s.nocs[m] > 0) & (s.nocs[m] < 1)).all(1)  # not clipped
        q, move = t.nocs[m][inside] - 0.5, (s.nocs[m] - t.nocs[m])[inside]
        a = np.block([[q[:, 1:2] ** 2, q[:, 1:2] * q[:, :1]],
                      [np.zeros((len(q), 1)), q[:, 1:2] * q[:, 2:]]])
        bc, *_ = np.linalg.lstsq(a, np.concatenate([move[:, 0], move[:, 2]]), rcond=None)
        assert np.abs(a @ bc - np.concatenate([move[:, 0], move[:, 2]])).max() < 1e-12
        assert np.abs(move[:, 1]).max() == 0.0
        coef.setdefault((seed, int(iid)), []).append(bc)
    for bc in coef.values():
        np.testing.assert_allclose(bc[0], bc[-1], atol=1e-12)
        assert abs(bc[0][0]) <= 0.36 and abs(bc[0][1]) <= 0.18, bc
    b, c = np.array([bc[0] for bc in coef.values()]).T
    assert min(b) < -0.01 < 0.01 < max(b) and min(c) < -0.01 < 0.01 < max(c), (b, c)


def test_tenth_heldout_model_masks_flicker_and_switch_ids():
    """heldout10, with mask errors (mask_px 3): each instance's mask is eroded or dilated by a
    width drawn anew in every frame (its area's change over its true outline's length spans
    more than 1.5 px over 8 frames for most instances, within 4 px of nothing: measured spans
    2.0-6.3, the largest change 3.7), and in 5% of the frames (of 4000 draws: 5.25%) two
    instances exchange their ids for that frame only (over 25 sequences of 8 frames with 3
    objects: 16 drawn, 15 told apart by their pixels; no switch is the frame before's)."""
    import cv2

    from fcop_ros.synthetic.world import ErrorFamilies, _id_switch

    rng = np.random.default_rng(0)
    mask = np.repeat(np.arange(4, dtype=np.uint16), 4)[None]
    out = [_id_switch(mask, [1, 2, 3], rng) for _ in range(4000)]
    moved = [o for o in out if np.any(o != mask)]
    assert 0.04 < len(moved) / len(out) < 0.06, len(moved)
    for o in moved:
        ids = {int(a): int(b) for a, b in zip(mask[0], o[0])}
        assert sum(a != b for a, b in ids.items()) == 2 and sorted(ids.values()) == [0, 1, 2, 3]

    spans, switched, kept = [], 0, 0
    for seed in range(25):
        truth, seen, _ = _held_out("heldout10", ErrorFamilies(mask_px=3), seed, 8, objects=3)
        widths, before = {}, {}
        for k, (t, s) in enumerate(zip(truth, seen)):
            wrong = {a: b for a, b in _true_ids(s, t).items() if a != b}
            kept += bool(wrong) and wrong == before
            before = wrong
            if wrong:
                switched += 1
                assert len(wrong) == 2 and wrong == {b: a for a, b in wrong.items()}, wrong
                continue
            for iid in np.unique(t.mask[t.mask > 0]):
                m = (t.mask == iid).astype(np.uint8)
                rim = m.sum() - cv2.erode(m, np.ones((3, 3), np.uint8)).sum()
                if rim >= 20:
                    widths.setdefault(int(iid), []).append(
                        (np.sum(s.mask == iid) - m.sum()) / rim)
        for w in widths.values():
            if len(w) >= 6:
                assert np.abs(w).max() < 4, w
                spans.append(np.ptp(w))
    assert 3 <= switched <= 20 and kept == 0, (switched, kept)
    assert np.mean(np.array(spans) > 1.5) > 0.8, spans


def test_a_sequence_can_draw_its_persistent_errors_anew_every_frame():
    """``renew`` (bench/world_accuracy.py --renew) makes an error that persists over a sequence
    one of each frame, as the window's diagnostic needs: a still camera sees the same shape
    mismatch and offset in every frame unless they are renewed, and a depth field whose
    successive frames correlate unless it is renewed (over the image, mean of 8 sequences,
    measured 0.74 and -0.04; a smooth field of few cells correlates by chance, -0.58 to 0.39
    per sequence)."""
    from fcop_ros.synthetic.world import ErrorFamilies, world_frames

    def frames(preset, renew):
        a, b = world_frames(preset, 3, 2, orbit_deg=0.0, renew=renew).frames
        return a, b, (a.mask > 0) & (b.mask > 0)

    for preset, image in (("only_shape", "nocs"), ("only_offset", "depth")):
        a, b, on = frames(preset, ())
        np.testing.assert_array_equal(getattr(a, image)[on], getattr(b, image)[on])
        a, b, on = frames(preset, (preset[5:],))
        assert not np.array_equal(getattr(a, image)[on], getattr(b, image)[on]), preset
    corr = {}
    for renew in ((), ("field",)):
        c = []
        for seed in range(8):
            clean = world_frames(ErrorFamilies(), seed, 1, orbit_deg=0.0).frames[0].depth
            a, b = world_frames("only_field", seed, 2, orbit_deg=0.0, renew=renew).frames
            on = np.isfinite(clean) & np.isfinite(a.depth) & np.isfinite(b.depth)
            c.append(np.corrcoef(a.depth[on] / clean[on], b.depth[on] / clean[on])[0, 1])
        corr[renew] = np.mean(c)
    assert corr[()] > 0.5 and abs(corr[("field",)]) < 0.25, corr
    with pytest.raises(ValueError, match="cannot renew"):
        world_frames("predicted", 0, 1, renew=("mask",))


def _through_lens_residuals(seen, truth, undistort):
    """|pinhole projection of the point the NOCS of ``seen`` name - the pixel taken back
    through ``undistort``| (px), and the same against the pixel itself, over the pixels well
    inside each instance whose depth is their point's."""
    import cv2

    pose = {o.instance_id: o for o in truth.objects}
    cx, cy = seen.principal_point
    lensed, pinhole = [], []
    for iid in np.unique(seen.mask[seen.mask > 0]):
        inner = cv2.erode((seen.mask == iid).astype(np.uint8), np.ones((11, 11), np.uint8))
        v, u = np.nonzero(inner)
        if len(v) < 20 or iid not in pose:
            continue
        o = pose[iid]
        x = o.scale * (seen.nocs[v, u] - 0.5) @ o.rotation.T + o.translation
        ok = np.abs(seen.depth[v, u] / x[:, 2] - 1) < 1e-9
        u, v, x = u[ok], v[ok], x[ok]
        pu, pv = cx + seen.focal * x[:, 0] / x[:, 2], cy + seen.focal * x[:, 1] / x[:, 2]
        xu, yu = undistort((u - cx) / seen.focal, (v - cy) / seen.focal)
        lensed.append(np.hypot(pu - (cx + seen.focal * xu), pv - (cy + seen.focal * yu)))
        pinhole.append(np.hypot(pu - u, pv - v))
    return np.concatenate(lensed), np.concatenate(pinhole)


def test_the_tuning_world_and_heldout11_take_their_images_through_a_lens():
    """The tuning world's camera has a residual distortion (``lens``, both presets: a Brown
    polynomial, k1 in +-0.01, k2 in +-0.005), heldout11's a division model with decentering:
    the points the NOCS name fall on their pixels through the sequence's lens, 99% within
    0.02 px (measured under 1e-4: bilinear in float64 within a surface; OpenCV's 1/32 px
    weights left points that move under 1/64 px where they were), not through a pinhole (99th
    percentile over 6 seeds: tuning 0.003-0.040 px, heldout11 0.03-0.43 px, its decentering
    moving points at the objects' radii more than the radial terms do); the lens is the same in
    every frame and none without the family (``lens`` 0: the frames are the pinhole's)."""
    from fcop_ros.synthetic.world import ErrorFamilies, _lens, world_frames

    fam = ErrorFamilies(lens=0.01)
    for variant in ("tuning", "heldout11"):
        off = []
        for seed in range(6):
            truth = world_frames(ErrorFamilies(), seed, 2, variant).frames
            seen = world_frames(fam, seed, 2, variant).frames
            for s, t in zip(seen, truth):
                lensed, pinhole = _through_lens_residuals(s, t, _lens(0.01, seed, variant))
                assert np.percentile(lensed, 99) < 0.02, (variant, seed)
                off.append(np.percentile(pinhole, 99))
            np.testing.assert_array_equal(truth[0].depth, world_frames(
                ErrorFamilies(lens=0.0), seed, 1, variant).frames[0].depth)
        assert max(off) > {"tuning": 0.03, "heldout11": 0.3}[variant], (variant, off)


def test_twelfth_heldout_model_errs_with_the_grazing_angle():
    """heldout12, with a depth field (field 0.03): the relative depth error on the objects is
    exactly (within 1e-12) c (1 - cos theta), theta the angle between the true normal and
    the viewing ray, so it grows with the grazing angle (measured over 6 seeds: |error| 7.8-15.5
    times larger where 1 - cos theta > 0.5 than where it is under 0.1); c drifts from frame to
    frame with the field (never the same twice) and takes both signs (measured -0.12 to
    +0.15); the tuning model's field does not follow the angle (correlation -0.62 to 0.29,
    heldout12's +-1)."""
    from fcop_ros.synthetic.world import ErrorFamilies, _grazing, world_frames

    coefs = []
    for seed in range(6):
        truth, seen, _ = _held_out("heldout12", ErrorFamilies(field=0.03, field_drift=0.6), seed)
        c = []
        for t, s in zip(truth, seen):
            g = _grazing(t)
            on = (t.mask > 0) & np.isfinite(g) & np.isfinite(t.depth)
            rel, g = s.depth[on] / t.depth[on] - 1, g[on]
            c.append(np.sum(rel * g) / np.sum(g * g))
            assert np.abs(rel - c[-1] * g).max() < 1e-12, seed
            assert np.abs(rel[g > 0.5]).mean() > 5 * np.abs(rel[g < 0.1]).mean(), seed
        assert c[0] != c[1], (seed, c)
        coefs += c
        tt, ts = (world_frames(f, seed, 1).frames[0]
                  for f in (ErrorFamilies(), ErrorFamilies(field=0.03, field_drift=0.6)))
        g = _grazing(tt)
        on = (tt.mask > 0) & np.isfinite(g) & np.isfinite(tt.depth)
        assert abs(np.corrcoef(ts.depth[on] / tt.depth[on] - 1, g[on])[0, 1]) < 0.9, seed
    assert min(coefs) < -0.05 and max(coefs) > 0.05, coefs


def test_twelfth_heldout_model_misregisters_each_objects_nocs_map():
    """heldout12, with a NOCS field (nocs_field 0.03): the masks are the truth's and each
    object's NOCS, well inside it, are the truth's taken bilinearly at the pixel moved by a
    shift of its box's diagonal times nocs_field / 2 per axis (within 1e-5; measured 1e-6,
    OpenCV's weights), kept for the sequence without field drift; over 6 seeds the shifts are
    0.0001-0.038 of the diagonal, both signs on both axes, and move the NOCS 0.006-0.045 rms."""
    import cv2
    from scipy import ndimage

    from fcop_ros.synthetic.world import ErrorFamilies

    shifts = []
    for seed, t, s, state, iid, m in _objects_of_kept_masks(
            "heldout12", ErrorFamilies(nocs_field=0.03), range(6)):
        ys, xs = np.nonzero(m)
        diag = np.hypot(np.ptp(ys) + 1, np.ptp(xs) + 1)
        shift = state.fields[("roi_shift", int(iid))] * 0.5 * 0.03 * diag
        r = int(np.ceil(np.abs(shift).max())) + 2
        inner = cv2.erode(m.astype(np.uint8), np.ones((2 * r + 1,) * 2, np.uint8),
                          borderType=cv2.BORDER_CONSTANT, borderValue=0)
        v, u = np.nonzero(inner)
        if len(v) < 20:
            continue
        want = np.stack([ndimage.map_coordinates(t.nocs[..., c],
                                                 [v + shift[1], u + shift[0]], order=1)
                         for c in range(3)], -1)
        assert np.abs(s.nocs[v, u] - want).max() < 1e-5, (seed, iid)
        shifts.append(shift / diag)
    shifts = np.array(shifts)
    assert np.abs(shifts).max() < 0.06, shifts
    assert (shifts.min(0) < -0.005).all() and (shifts.max(0) > 0.005).all(), shifts


def test_twelfth_heldout_model_pastes_each_objects_nocs_from_a_28x28_grid():
    """heldout12, with per-pixel NOCS noise (1e-12, so that the blocks show): each object's
    NOCS are constant over blocks of its box's size over 28 pixels (at most 28 x 28 values;
    the runs along a row are box width / 28 long within 10%, measured within 2%) and off the
    truth by about half a block's worth of their gradient (measured 0.006-0.020 rms); the
    ``sensor`` preset's NOCS stay the camera's truth, deep inside the objects exactly those
    of a frame with its camera alone."""
    from dataclasses import replace

    from fcop_ros.synthetic.world import WORLD_PRESETS, ErrorFamilies, world_frame

    runs = []
    for seed in range(4):
        t = world_frame(ErrorFamilies(), seed, "heldout12")
        s = world_frame(ErrorFamilies(nocs_pixel=1e-12), seed, "heldout12")
        np.testing.assert_array_equal(s.mask, t.mask)
        for iid in np.unique(t.mask[t.mask > 0]):
            m = t.mask == iid
            ys, xs = np.nonzero(m)
            width = np.ptp(xs) + 1
            assert len(np.unique(s.nocs[m].round(8), axis=0)) <= 28 * 28
            assert 0.003 < np.sqrt(np.mean((s.nocs[m] - t.nocs[m]) ** 2)) < 0.03
            if width < 56:
                continue
            row = s.nocs[:, xs.min():xs.max() + 1]
            inside = m[:, xs.min():xs.max() + 1]
            both = inside[:, 1:] & inside[:, :-1]
            steps = both & np.any(np.abs(np.diff(row, axis=1)) > 1e-8, axis=-1)
            runs.append(both.sum() / steps.sum() / (width / 28))
        camera = replace(ErrorFamilies(), principal_point=0.02, lens=0.01)
        sensor = world_frame("sensor", seed, "heldout12")
        alone = world_frame(camera, seed, "heldout12")
        assert sensor.principal_point == alone.principal_point
        deep = cv2_erode((sensor.mask > 0) & (sensor.mask == alone.mask), 9)
        np.testing.assert_array_equal(sensor.nocs[deep], alone.nocs[deep])
    assert len(runs) >= 5 and np.abs(np.array(runs) - 1).max() < 0.1, runs
    assert WORLD_PRESETS["sensor"].nocs_pixel == 0 == WORLD_PRESETS["sensor"].nocs_field


def test_twelfth_heldout_model_masks_err_only_where_objects_meet_the_table():
    """heldout12, with mask errors (mask_px 3): each instance's mask grows into the background
    or gives its own pixels up only where the background is within 2% of the object's depth
    (measured at most 2.0%: its base on the table) and within 6 px of the true outline; grown
    pixels keep the table's depth and take the NOCS of the object's nearest pixel; the width
    is drawn anew in every frame (over 8 seeds of 3 frames: 39 instances grown and 35 cut,
    74 of 84 changed); the tuning model erodes and dilates all round."""
    from scipy import ndimage

    from fcop_ros.synthetic.world import ErrorFamilies, world_frame

    grown = cut = changed = total = 0
    for seed in range(8):
        truth, seen, _ = _held_out("heldout12", ErrorFamilies(mask_px=3), seed, 3)
        for t, s in zip(truth, seen):
            z = t.depth
            for iid in np.unique(t.mask[t.mask > 0]):
                m = t.mask == iid
                g, c = (s.mask == iid) & ~m, m & (s.mask != iid)
                total += 1
                changed += bool(g.any() or c.any())
                if g.any():
                    grown += 1
                    d, (iy, ix) = ndimage.distance_transform_edt(~m, return_indices=True)
                    assert d[g].max() <= 6 and (t.mask[g] == 0).all()
                    assert np.abs(z[g] / z[iy[g], ix[g]] - 1).max() <= 0.02 + 1e-12
                    np.testing.assert_array_equal(s.nocs[g], t.nocs[iy[g], ix[g]])
                    np.testing.assert_array_equal(s.depth[g], t.depth[g])
                if c.any():
                    cut += 1
                    bg = (t.mask == 0) & np.isfinite(z)
                    d, (iy, ix) = ndimage.distance_transform_edt(~bg, return_indices=True)
                    assert d[c].max() <= 6 and (s.mask[c] == 0).all()
                    assert np.abs(z[iy[c], ix[c]] / z[c] - 1).max() <= 0.02 + 1e-12
    assert grown >= 20 and cut >= 20 and changed > 0.75 * total, (grown, cut, changed, total)
    # The tuning model's masks grow over a background far behind, heldout12's never.
    far = {}
    for v in ("tuning", "heldout12"):
        n = 0
        for seed in range(4):
            t = world_frame(ErrorFamilies(), seed, v)
            s = world_frame(ErrorFamilies(mask_px=3), seed, v)
            for iid in np.unique(t.mask[t.mask > 0]):
                grown = (s.mask == iid) & (t.mask == 0) & np.isfinite(t.depth)
                _, (iy, ix) = ndimage.distance_transform_edt(t.mask != iid, return_indices=True)
                n += int(np.sum(grown & (t.depth > 1.05 * t.depth[iy, ix])))
        far[v] = n
    assert far["heldout12"] == 0 and far["tuning"] > 100, far


@pytest.mark.parametrize("variant", ["heldout12", "heldout13"])
def test_twelfth_and_thirteenth_heldout_models_keep_the_tuning_scene_truth_and_camera(variant):
    """heldout12 and heldout13 see the tuning model's scene, draw the same error strengths and
    keep its camera (principal point and lens) for every seed."""
    from fcop_ros.synthetic.world import world_frames

    for seed in range(4):
        for preset in ("sensor", "predicted"):
            a, b = (world_frames(preset, seed, 1, v) for v in ("tuning", variant))
            assert a.errors == b.errors and a.size == b.size
            fa, fb = a.frames[0], b.frames[0]
            assert fa.focal == fb.focal and fa.principal_point == fb.principal_point
            assert [(o.instance_id, o.category, o.scale) for o in fa.objects] == [
                (o.instance_id, o.category, o.scale) for o in fb.objects]
            np.testing.assert_array_equal([o.rotation for o in fa.objects],
                                          [o.rotation for o in fb.objects])


def test_thirteenth_heldout_model_depth_noise_grows_with_the_square_of_depth():
    """heldout13, with per-pixel depth noise alone (depth_pixel 0.01): the relative noise is
    0.01 times the true depth in metres (a stereo pair's), the tuning model's 0.01 at any depth;
    measured over the objects of 12 scenes at 0.4-2 m, least squares through the origin of the
    relative noise's std per object on its median depth: 0.0100, each object's std over its
    depth 0.0097-0.0104 (tuning: each object's std 0.0097-0.0103 at any depth)."""
    from fcop_ros.synthetic.world import ErrorFamilies

    std, z = {"tuning": [], "heldout13": []}, {"tuning": [], "heldout13": []}
    for v in std:
        for seed in range(12):
            truth, seen, state = _held_out(v, ErrorFamilies(depth_pixel=0.01), seed, 1)
            t, f = truth[0], seen[0]
            for iid in np.unique(t.mask[t.mask > 0]):
                if state.fields.get(("see_through", int(iid))):
                    continue
                m = (t.mask == iid) & np.isfinite(f.depth)
                r = f.depth[m] / t.depth[m] - 1
                std[v].append(np.std(r[np.abs(r) < 0.1]))
                z[v].append(np.median(t.depth[m]))
    s13, z13 = np.array(std["heldout13"]), np.array(z["heldout13"])
    assert z13.min() < 0.8 and z13.max() > 1.4, z13
    slope = float(s13 @ z13 / (z13 @ z13))
    assert 0.0095 < slope < 0.0105, slope
    assert np.all(np.abs(s13 / z13 - 0.01) < 0.0015), s13 / z13
    assert np.all(np.abs(np.array(std["tuning"]) - 0.01) < 0.0015), std["tuning"]


def test_thirteenth_heldout_model_sees_through_some_objects_to_the_table():
    """heldout13, with per-pixel depth noise: about one object in seven (kept for the sequence)
    reads the table behind it over a part of its pixels that moves from frame to frame; that
    depth only ever moves back. Measured over 40 scenes of two frames (depth_pixel 1e-9): 23
    of 138 objects, each reading the table on 14-47% of its pixels per frame (median 23%), the
    others on none."""
    from fcop_ros.synthetic.world import ErrorFamilies

    seen_through, others, shares = 0, 0, []
    for seed in range(40):
        truth, seen, state = _held_out("heldout13", ErrorFamilies(depth_pixel=1e-9), seed)
        for iid in np.unique(truth[0].mask[truth[0].mask > 0]):
            flag = state.fields.get(("see_through", int(iid)))
            for t, f in zip(truth, seen):
                m = (t.mask == iid) & np.isfinite(t.depth)
                r = f.depth[m] / t.depth[m] - 1
                assert r.min() > -1e-6, (seed, iid)  # never in front of the object
                moved = r > 1e-6
                if flag:
                    shares.append(moved.mean())
                else:
                    assert not moved.any(), (seed, iid)
            seen_through += bool(flag)
            others += not flag
    assert 0.08 < seen_through / (seen_through + others) < 0.25, (seen_through, others)
    assert 0.1 < min(shares) and np.median(shares) < 0.35 and max(shares) < 0.55, shares


def test_thirteenth_heldout_model_redraws_the_depth_offset_in_every_frame():
    """heldout13, with an additive depth offset alone (offset 0.02 m): each frame's offset is
    drawn anew (a shift fitted frame by frame), the tuning model's kept for the sequence."""
    from fcop_ros.synthetic.world import ErrorFamilies

    for v, changes in (("tuning", False), ("heldout13", True)):
        for seed in range(3):
            truth, seen, _ = _held_out(v, ErrorFamilies(offset=0.02), seed, 3)
            off = [np.nanmedian(f.depth - t.depth) for t, f in zip(truth, seen)]
            assert (np.ptp(off) > 1e-4) == changes, (v, seed, off)


def test_thirteenth_heldout_model_warps_each_objects_nocs_space():
    """heldout13, with a NOCS distortion alone (nocs_field 0.02): each object's NOCS move by a
    function of the NOCS themselves, kept for the sequence (the same NOCS point moves alike in
    every frame, wherever it is in the image), about as much as the tuning field moves them
    (rms per axis over the objects, measured on 6 scenes: 0.026, the tuning field 0.019)."""
    from fcop_ros.synthetic.world import ErrorFamilies, _bumps

    moves = {"tuning": [], "heldout13": []}
    for v in moves:
        for seed in range(6):
            truth, seen, state = _held_out(v, ErrorFamilies(nocs_field=0.02), seed, 2)
            for t, f in zip(truth, seen):
                obj = t.mask > 0
                moves[v].append(f.nocs[obj] - t.nocs[obj])
                if v != "heldout13":
                    continue
                for iid in np.unique(t.mask[obj]):
                    m = t.mask == iid
                    want = np.clip(t.nocs[m] + 0.02 * _bumps(t.nocs[m], *state.fields[
                        ("warp", int(iid))]), 0, 1)
                    np.testing.assert_allclose(f.nocs[m], want, atol=1e-12)
    rms = {v: float(np.sqrt(np.mean(np.concatenate(m) ** 2))) for v, m in moves.items()}
    assert 0.01 < rms["heldout13"] < 0.04 and 0.01 < rms["tuning"] < 0.04, rms
