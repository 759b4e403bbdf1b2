"""The node's focal bookkeeping without a node: the tracker (window, image size, kept frames,
publish gate) and which depth stamps got their CameraInfo."""
import numpy as np

from fcop_ros import WindowOptions
from fcop_ros.core.estimator import FocalEstimate
from fcop_ros.ros.answers import DepthAnswers
from fcop_ros.ros.tracker import FocalTracker


def estimate(focal, std_rel=0.01, size=(640, 480), support=500):
    return FocalEstimate(focal, (size[0] / 2, size[1] / 2), size, inlier_count=support,
                         std_rel=std_rel, votes=np.ones(1000), instances=[object()])


def empty(size=(640, 480)):
    return FocalEstimate(None, (size[0] / 2, size[1] / 2), size, reason="nothing")


def tracker(frames=5, max_uncertainty=0.05, focal_range=(100.0, 5000.0), **kw):
    return FocalTracker(WindowOptions(max_frames=frames, **kw), max_uncertainty, focal_range)


def test_publishable_carries_the_windows_focal_and_image_size_and_drops_pixel_data():
    t = tracker()
    assert t.publishable is None and "no frames yet" in t.held_back()
    step = t.add(estimate(600.0), 0.0)
    assert step.window_estimate is t.current
    assert step.resized_from is None and step.kept_size is None
    assert step.ready is t.publishable
    assert (step.ready.focal, step.ready.width, step.ready.height) == (600.0, 640, 480)
    kept = t._history[-1][0]  # what a later re-evaluation sees
    assert kept.instances == [] and kept.votes.size == 0 and kept.focal == 600.0


def test_another_size_starts_a_new_window_only_with_a_focal_of_its_own():
    t = tracker()
    for k in range(3):
        t.add(estimate(600.0), k)
    step = t.add(empty((320, 240)), 3)
    assert step.kept_size == (640, 480) and step.window_estimate is None and len(t) == 3
    assert t.publishable.width == 640  # the old size's focal still answers 640x480 images
    step = t.add(estimate(300.0, size=(320, 240)), 4)
    assert step.resized_from == (640, 480) and len(t) == 1 and t.size == (320, 240)
    assert abs(t.publishable.focal - 300.0) < 1e-9 and t.publishable.width == 320
    t.reset()
    assert t.publishable is None and len(t) == 0
    # An empty window takes any size, with or without a focal.
    assert t.add(empty((640, 480)), 5).kept_size is None and t.size == (640, 480)


def test_another_frame_id_starts_a_new_window_as_another_size_does():
    """A new user's audit (25 Nov 2026): one frame in another camera's frame_id joined the
    window and got a CameraInfo at the old camera's focal, said nowhere. Another frame_id is
    another camera: a frame of it with a focal of its own starts a new window (said and
    counted), one without is dropped and the window kept."""
    from fcop_ros.ros.frame_outcome import frame_outcome

    t = tracker()
    for k in range(3):
        t.add(estimate(600.0), k, "cam_a")
    assert t.publishable.frame_id == "cam_a" and len(t) == 3
    stray = empty()
    said = frame_outcome(stray, t.add(stray, 3, "cam_b"), "cam_b")
    assert not said.kept and said.dropped == {"other_frame_id_no_evidence": 1} and len(t) == 3
    assert "the window keeps its frames in 'cam_a'" in said.log[0][2]
    other = estimate(450.0)
    step = t.add(other, 4, "cam_b")
    said = frame_outcome(other, step, "cam_b")
    assert step.reframed_from == "cam_a" and step.resized_from is None and len(t) == 1
    assert t.publishable.frame_id == "cam_b" and abs(t.publishable.focal - 450.0) < 1e-9
    assert said.warnings == {"frame_id_changed": 1}
    assert [e[:2] for e in said.log] == [("warn", "frame_id_changed")]
    assert "from 'cam_a' to 'cam_b' (another camera?): new focal window" in said.log[0][2]
    # The same frame_id again: no change.
    assert t.add(estimate(450.0), 5, "cam_b").reframed_from is None and len(t) == 2


def test_a_window_without_evidence_takes_the_next_size_too():
    """A first frame without evidence (a 1x1 test image, a camera still starting) held the
    window's size: every frame of the real size without evidence was then dropped as
    other_size_no_evidence, which says a window was kept that held nothing (until 25 Nov 2026).
    A window without a focal keeps no size against another."""
    t = tracker()
    t.add(empty((1, 1)), 0)
    step = t.add(empty((640, 480)), 1)
    assert step.kept_size is None and step.resized_from == (1, 1) and t.size == (640, 480)
    assert len(t) == 1
    t.add(estimate(600.0), 2)
    assert t.add(empty((320, 240)), 3).kept_size == (640, 480)


def test_new_window_settings_re_evaluate_the_kept_frames():
    """Five frames at 600 px, the window shrunk to 2 and grown to 5 again: it gets all five
    back; settings that reach only the gate keep the window as it is."""
    t = tracker(frames=5)
    for k in range(5):
        t.add(estimate(600.0 * (1 + 0.001 * k)), k)
    window = t.window
    t.configure(WindowOptions(max_frames=5), 0.05, (100.0, 5000.0))
    assert t.window is window
    t.configure(WindowOptions(max_frames=2), 0.05, (100.0, 5000.0))
    assert len(t) == 2 and t.publishable is not None
    t.configure(WindowOptions(max_frames=5), 0.05, (100.0, 5000.0))
    assert len(t) == 5 and t.current.frames == 5
    t.configure(WindowOptions(max_frames=5, min_frames=5), 0.05, (100.0, 5000.0))
    assert t.publishable is not None  # five frames with a focal meet min_frames 5


def test_the_gate_holds_back_an_uncertain_or_out_of_range_focal_and_frees_it_again():
    t = tracker(max_uncertainty=0.005)
    t.add(estimate(600.0, std_rel=0.01), 0.0)
    assert t.publishable is None and "above max_uncertainty 0.005" in t.held_back()
    t.configure(t.window.options, 0.05, (100.0, 5000.0))
    assert abs(t.publishable.focal - 600.0) < 1e-9 and t.held_back() == ""
    t.configure(t.window.options, 0.05, (700.0, 5000.0))
    assert t.publishable is None and "outside focal_range [700, 5000]" in t.held_back()


def test_each_depth_stamp_is_answered_once_and_a_late_answer_never_goes_back_in_time():
    a = DepthAnswers(keep=3)
    a.unanswered(10)
    a.unanswered(20)
    assert a.owed(10) and a.owed(20) and not a.answered(10)
    a.answer(20)
    assert a.answered(20) and not a.owed(20)
    assert not a.owed(10)  # 20 went out already: 10's CameraInfo would go out of order
    for s in (30, 40, 50):
        a.answer(s)
    assert not a.answered(20) and a.answered(50)  # only the last three are kept
    a.forget()
    a.unanswered(-5)  # a restarted clock: anything goes again
    assert a.owed(-5) and not a.answered(50)


def test_frame_outcome_says_what_each_step_means_without_a_node():
    """The node's words for a frame, from the tracker's step alone: a stray size drops the frame,
    a frame without evidence is counted, a new size and a restart are said every time."""
    from fcop_ros.ros.frame_outcome import frame_outcome

    t = tracker()
    for k in range(3):
        said = frame_outcome(estimate(600.0), t.add(estimate(600.0), k))
        assert said.kept and not said.dropped and not said.log
    stray = empty((320, 240))
    said = frame_outcome(stray, t.add(stray, 3))
    assert not said.kept and said.dropped == {"other_size_no_evidence": 1}
    assert said.log == (("warn", "other_size_no_evidence",
                         "dropped a 320x240 frame without focal evidence (nothing); "
                         "the window keeps its 640x480 frames"),)
    small = estimate(300.0, size=(320, 240))
    said = frame_outcome(small, t.add(small, 4))
    assert said.kept and [e[:2] for e in said.log] == [("info", "resized")]
    assert "from 640x480 to 320x240: new focal window" in said.log[0][2]
    nothing = empty((320, 240))
    said = frame_outcome(nothing, t.add(nothing, 5))
    assert said.kept and said.dropped == {"no_evidence": 1}
    mirrored = estimate(300.0, size=(320, 240))
    mirrored.mirrored = [3]
    said = frame_outcome(mirrored, t.add(mirrored, 6))
    assert said.warnings == {"mirrored_nocs": 1} and "instance(s) [3]" in said.log[0][2]


def test_frame_outcome_says_a_zoom_each_time_the_window_restarts():
    from fcop_ros.ros.frame_outcome import frame_outcome

    t = tracker(frames=30)
    for k in range(10):
        t.add(estimate(600.0), k)
    lines = []
    for k in range(10, 20):
        est = estimate(750.0)
        lines += [e for e in frame_outcome(est, t.add(est, k)).log if e[1] == "zoom"]
    assert len(lines) == 1 and lines[0][0] == "info", lines
    assert lines[0][2].startswith("focal length changed (zoom?): window restarted")


def test_frame_outcome_says_when_the_window_keeps_its_frames_through_a_zoom():
    """Objects whose image radii and extents grow by the focal lengths' 25%: the node says the
    zoom it measured and that the window kept its frames, and the window holds all 20."""
    from fcop_ros.ros.frame_outcome import frame_outcome

    t = tracker(frames=30)
    lines = []
    for k in range(20):
        zoom = 1.25 if k >= 10 else 1.0
        est = estimate(600.0 * zoom)
        est.object_radii = {1: 40.0 * zoom * (1 + 0.002 * (k % 3)), 2: 25.0 * zoom}
        est.object_extents = {i: r * 1.5 for i, r in est.object_radii.items()}
        lines += [e for e in frame_outcome(est, t.add(est, k)).log if e[1] == "zoom"]
    assert len(lines) == 1, lines
    assert lines[0][2] == ("focal length changed (zoom?): x1.251 as the objects' "
                           "image sizes show; the window keeps its 12 frames at the new focal, "
                           "now at 750.3 px")
    assert len(t.window) == 20 and abs(t.current.focal / 750.0 - 1) < 1e-3
