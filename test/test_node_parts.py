"""The node's plain parts, each alone: the parameter schema, the synchroniser step in the node's
words, the one-slot worker, the diagnostics builder and the intrinsics of its CameraInfo (no DDS,
no node)."""

import threading
from collections import Counter

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import ParameterType

from fcop_ros.core import WindowEstimate
from fcop_ros.ros.diagnostics import DiagnosticsInput, Rates, RateWindow, status_fields
from fcop_ros.ros.params import (
    PARAMETERS,
    READ_ONLY,
    ParameterError,
    ParamSpec,
    allowed,
    check_combination,
    check_value,
    defaults,
    descriptor,
)
from fcop_ros.ros.frame_estimate import estimate_frame
from fcop_ros.ros.intrinsics import Refused
from fcop_ros.ros.intake import FLOWING_SECONDS, Intake
from fcop_ros.ros.sync import StampSynchronizer
from fcop_ros.ros.worker import LatestSlotWorker

# ----- the parameter schema


def test_every_spec_says_one_kind_of_limit_that_fits_its_type():
    for name, spec in PARAMETERS.items():
        assert isinstance(spec, ParamSpec) and spec.description, name
        kinds = [spec.range is not None, bool(spec.choices), bool(spec.text_rule)]
        assert sum(kinds) <= 1, name
        if isinstance(spec.default, bool):
            assert not any(kinds), name
        elif isinstance(spec.default, (int, float)):
            lo, hi = spec.range
            assert lo <= spec.default <= hi and type(lo) is type(spec.default), name
        else:
            assert spec.choices or spec.text_rule, name
            assert not spec.choices or spec.default in spec.choices, name
        assert check_value(name, spec.default) == spec.default  # every default is allowed


def test_descriptor_carries_range_and_read_only_for_rclpy_to_enforce():
    d = descriptor("window_frames")
    assert (d.integer_range[0].from_value, d.integer_range[0].to_value) == (
        1,
        1000,
    ) and not d.read_only
    d = descriptor("focal_min")
    assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == (1.0, 1e6)
    assert "relative" in descriptor("noise_bound_mode").additional_constraints
    assert READ_ONLY == {"seed", "set_camera_info_service"} and all(
        descriptor(n).read_only for n in READ_ONLY
    )
    # The type comes from the default at declaration: the descriptor leaves it unset.
    assert descriptor("seed").type == ParameterType.PARAMETER_NOT_SET


@pytest.mark.parametrize(
    "name, value, words",
    [
        ("window_frames", 0, "an integer in [1, 1000]"),
        ("window_frames", 2.5, "an integer in [1, 1000]"),
        ("sync_mode", "fuzzy", "one of exact, approximate"),
        ("camera_name", "my camera", "a string (letters, digits, _ and -)"),
        ("publish_poses", "yes", "true or false"),
    ],
)
def test_check_value_names_parameter_value_and_what_is_allowed(name, value, words):
    with pytest.raises(ParameterError) as err:
        check_value(name, value)
    assert (
        str(err.value) == f"parameter {name}={value!r} is not allowed: {words}"
        and allowed(name) == words
    )


def test_an_integer_for_a_double_is_taken_as_a_double():
    assert check_value("focal_min", 300) == 300.0 and type(check_value("focal_min", 300)) is float


def test_run_time_change_sets_hold_every_parameter_their_builders_read_under_any_choice():
    """A parameter read only under one choice (sync_slop only when sync_mode is approximate)
    would be missed by the sets taken at the defaults, and its change ignored at run time."""
    import itertools

    from fcop_ros.ros import params as pm

    builders = {pm.estimator_options: pm.ESTIMATOR_PARAMETERS, pm.window_options:
                pm.WINDOW_PARAMETERS, pm.gate_settings: pm.GATE_PARAMETERS,
                pm.sync_settings: pm.SYNC_PARAMETERS}
    chosen = [n for n, spec in PARAMETERS.items() if spec.choices]
    for picks in itertools.product(*(PARAMETERS[n].choices for n in chosen)):
        values = {**defaults(), **dict(zip(chosen, picks))}
        for build, names in builders.items():
            assert pm._read_by(build, values) == names, (build.__name__, picks)


def test_combination_rules():
    p = defaults()
    assert check_combination(p) == ""
    assert "below focal_max" in check_combination({**p, "focal_min": 30000.0})
    assert "(0, 0.5]" in check_combination({**p, "noise_bound": 0.9})
    assert check_combination({**p, "noise_bound": 0.9, "noise_bound_mode": "absolute"}) == ""
    # Switching an absolute bound of 5 px to relative blames the switch, the parameter being set
    absolute = {**p, "noise_bound": 5.0, "noise_bound_mode": "relative"}
    assert check_combination(absolute, changed=("noise_bound_mode",)).startswith(
        "parameter noise_bound_mode='relative' is not allowed: noise_bound=5 is no fraction")
    assert check_combination(absolute, changed=("noise_bound",)).startswith(
        "parameter noise_bound=5.0 is not allowed")
    assert check_combination({**p, "principal_point_x": 700.0}) == ""  # image size not known yet
    assert "[0, 639]" in check_combination({**p, "principal_point_x": 700.0}, (640, 480))


# ----- the synchroniser step, in the node's words

INPUT_NAMES = ("depth", "nocs", "mask")
SEC, FRAME_DT = 1_000_000_000, 33_333_333


def _steps(sync, messages, intake=None):
    """Each (input, stamp[, arrival time s]) through one Intake (a new one on ``sync`` unless
    given); arrival defaults to the stamp."""
    intake = intake or Intake(sync, INPUT_NAMES)
    return [intake.add(m[0], m[1], f"{INPUT_NAMES[m[0]]}@{m[1]}",
                       m[2] if len(m) > 2 else m[1] / SEC) for m in messages]


def _slow_network(frames, delay, until=None):
    """(input, stamp, arrival s) in arrival order: depth at 30 Hz, NOCS and mask for every 6th
    frame before frame ``until``, ``delay(k)`` seconds after the depth, with its stamp (a
    segmentation network slower than the camera)."""
    events = []
    for k in range(frames):
        events.append((k / 30, 0, k * FRAME_DT))
        if k % 6 == 0 and (until is None or k < until):
            late = k / 30 + delay(k)
            events += [(late, 1, k * FRAME_DT), (late, 2, k * FRAME_DT)]
    return [(i, t, now) for now, i, t in sorted(events)]


def _lines(steps, level=None):
    return {key: text for st in steps for lv, key, text in st.log if level in (None, lv)}


def test_intake_names_the_silent_input_and_queue_size_when_a_queue_overflows():
    steps = _steps(StampSynchronizer(3, queue_size=2),
                   [(0, 10 * SEC + k * FRAME_DT) for k in range(3)])
    assert [st.dropped for st in steps] == [{}, {}, {"sync_queue_full": 1}]
    # Inputs that never sent are not told to raise queue_size (a trial's log said both).
    assert steps[2].log == (("warn", "sync_queue_full", (
        "dropped 1 message(s) in the synchroniser: queue full (depth 1); nothing "
        "received from nocs and mask yet (are they published, and the node's topics remapped "
        "to theirs?)")),)
    assert not any(st.sets or st.jumped for st in steps)
    assert [len(st.accepted) for st in steps] == [1, 1, 1]  # each passed the stamp check


def test_intake_tells_a_stopped_input_from_a_late_one():
    """The mask sent once, then nothing: within SILENT_SECONDS it may only be late, and
    queue_size is the hint; after them it is named as stopped."""
    sync = StampSynchronizer(3, queue_size=2)
    intake = Intake(sync, INPUT_NAMES)
    first = [(2, 10 * SEC, 10.0)]  # a mask whose depth and NOCS never come
    late = [(i, 10 * SEC + k * FRAME_DT, 10.0 + k / 30) for k in range(1, 4) for i in (0, 1)]
    text = " ".join(t for st in _steps(None, first + late, intake) for _, _, t in st.log)
    assert "nothing from mask to match them: silent, or later than queue_size (2)" in text
    stopped = [(i, 10 * SEC + k * FRAME_DT, 16.0 + k / 30) for k in range(4, 7) for i in (0, 1)]
    text = " ".join(t for st in _steps(None, stopped, intake) for _, _, t in st.log)
    assert "nothing from mask for 6 s (stopped?)" in text and "raise queue_size" not in text


def test_intake_counts_an_outlier_stamp_per_input_and_says_where_the_clock_was():
    messages = [(i, 0 if (i, k) == (2, 2) else 10 * SEC + k * FRAME_DT, 10 + k / 30)
                for k in range(5) for i in range(3)]
    steps = _steps(StampSynchronizer(3), messages)
    dropped = sum((st.dropped for st in steps), Counter())
    assert dropped == {"outlier_stamp_mask": 1, "sync_unmatched": 2}
    # Inputs of one rate: the depth and NOCS left without their mask are a lost frame, though
    # frames matched just before.
    assert _lines(steps, "warn") == {
        "outlier_2": ("dropped 1 mask message(s) with an outlier stamp (0.000 s; the "
                      "mask stamps before were at 10.033 s)"),
        "sync_unmatched": ("dropped 2 message(s) in the synchroniser: unmatched "
                           "(depth 1, nocs 1)")}
    assert not _lines(steps, "info")
    assert sum(len(st.sets) for st in steps) == 4 and not any(st.jumped for st in steps)


def test_intake_warns_when_the_slowest_input_is_the_one_dropped_while_frames_match():
    """The re-run trial: NOCS and mask 265 ms late with queue_size 8: 33 of 125 NOCS frames
    matched, and the lost NOCS were said once at INFO as expected flow. Every message of the
    slowest input should make a frame: its drops are a WARN."""
    # 10 s; the network's delay varies: 250 or 300 ms.
    messages = _slow_network(300, lambda k: 0.25 if k % 12 else 0.30)
    steps = _steps(StampSynchronizer(3, queue_size=8), messages)
    assert sum(len(st.sets) for st in steps) == 25  # those 250 ms late
    first = next(n for n, st in enumerate(steps) if st.sets)  # frames flow from here on
    warned = " ".join(text for st in steps[first + 1:] for lv, key, text in st.log
                      if (lv, key) == ("warn", "sync_unmatched"))
    assert "unmatched (nocs 1)" in warned and "unmatched (mask 1)" in warned
    flow = " ".join(_lines(steps, "info").values())  # the faster depth's drops only
    assert "(depth " in flow and "nocs" not in flow.split("(e.g.")[0]


def test_intake_measures_the_late_inputs_delay_and_says_the_queue_size_it_needs():
    """NOCS and mask 250 ms after their 30 Hz depth with the default queue_size 5: nothing can
    match, and the WARN says how large queue_size must be, once a late NOCS has come."""
    intake = Intake(StampSynchronizer(3, queue_size=5), INPUT_NAMES)
    steps = _steps(None, _slow_network(60, lambda k: 0.25), intake)
    assert not any(st.sets for st in steps)
    assert intake.queue_advice() == ("nocs comes 250 ms after the depth of its stamp, at 30 Hz: "
                                     "queue_size must be above 7.5")
    full = [text for st in steps for lv, key, text in st.log if key == "sync_queue_full"]
    assert full[-1].endswith("(nocs comes 250 ms after the depth of its stamp, at 30 Hz: "
                             "queue_size must be above 7.5)")
    intake.sync.configure(queue_size=10)
    assert intake.queue_advice() == ""  # the queue covers it
    # Approximate matching: NOCS and mask stamped 3 ms off their depth's are found within slop.
    jittered = [(i, t + (3_000_000 if i else 0), now)
                for i, t, now in _slow_network(60, lambda k: 0.25)]
    intake = Intake(StampSynchronizer(3, queue_size=5, slop=0.01), INPUT_NAMES)
    _steps(None, jittered, intake)
    assert intake.queue_advice() == ("nocs comes 250 ms after the depth of its stamp, at 30 Hz: "
                                     "queue_size must be above 7.5")


def test_intake_names_the_input_the_late_one_came_after():
    """A hostile user's trial: the advice named the input whose rate it used ('mask comes 26 ms
    after the nocs', of a mask logged with its NOCS), not the one that came first. Depth, mask
    100 ms later and NOCS 250 ms later, all at 30 Hz: NOCS is 250 ms after the depth."""
    intake = Intake(StampSynchronizer(3, queue_size=5), INPUT_NAMES)
    events = sorted((k / 30 + late, i, 10 * SEC + k * FRAME_DT)
                    for k in range(60) for i, late in ((0, 0.0), (2, 0.1), (1, 0.25)))
    _steps(None, [(i, t, now) for now, i, t in events], intake)
    assert intake.queue_advice() == ("nocs comes 250 ms after the depth of its stamp, at 30 Hz: "
                                     "queue_size must be above 7.5")


def test_intake_forgets_a_delay_once_the_input_comes_first():
    """A newcomer's review: an input late once kept its old delay when it later came first
    for its stamps, so the advice quoted a delay that no longer held."""
    intake = Intake(StampSynchronizer(3, queue_size=5), INPUT_NAMES)
    _steps(None, _slow_network(60, lambda k: 0.25), intake)
    assert "nocs comes 250 ms" in intake.queue_advice()
    # The network catches up: NOCS and mask of each stamp come 10 ms before its depth.
    after = [(i, t + 60 * FRAME_DT, now + 2.0 - (0.01 if i else 0.0))
             for i, t, now in _slow_network(60, lambda k: 0.0)]
    _steps(None, sorted(after, key=lambda m: m[2]), intake)
    assert intake.queue_advice() == ""


def test_intake_takes_a_looped_bags_repeated_stamps_for_no_delay():
    """A hostile user's trial: all inputs of each stamp together, but a 2 s bag looped. The
    second lap's stamps were matched with the first lap's arrivals, and the advice read 'mask
    comes 2002 ms after the nocs of its stamp: queue_size must be above 60.1'."""
    intake = Intake(StampSynchronizer(3, queue_size=5), INPUT_NAMES)
    for lap in range(2):
        _steps(None, [(i, 10 * SEC + k * FRAME_DT, lap * 2.0 + k / 30 + i / 1000)
                      for k in range(60) for i in range(3)], intake)
        assert intake.queue_advice() == ""


def test_intake_counts_what_a_smaller_queue_drops():
    """A newcomer's review: messages a run-time queue_size cut dropped reached the
    synchroniser's stats but not the node's count of dropped input."""
    intake = Intake(StampSynchronizer(3, queue_size=5), INPUT_NAMES)
    _steps(None, [(0, 10 * SEC + k * FRAME_DT) for k in range(5)], intake)
    assert intake.configure(2, 0.0) == {"sync_queue_full": 3}
    assert intake.sync.stats.dropped["queue_full"] == 3
    assert intake.configure(8, 0.01) == {} and intake.sync.slop_ns == 10_000_000


def test_intake_reports_a_jump_back_once_for_the_node_to_reset():
    messages = [(i, t * SEC + k * FRAME_DT, 20 + n / 10) for n, (t, k, i) in enumerate(
        (t, k, i) for t in (10, 2) for k in range(4) for i in range(3))]
    steps = _steps(StampSynchronizer(3), messages)
    jumps = [n for n, st in enumerate(steps) if st.jumped]
    assert len(jumps) == 1 and steps[jumps[0]].log == (("warn", "time_jump",
        "time jumped back (looped bag?): synchroniser and window reset"),)
    # The held depth messages that confirmed the jump are released with it, then matched.
    assert [m[1] for m in steps[jumps[0]].accepted] == [2 * SEC + k * FRAME_DT for k in range(3)]
    assert sum(len(st.sets) for st in steps) == 8


def test_intake_takes_a_slower_nocs_network_as_flow_and_warns_when_it_goes_silent():
    """30 Hz depth; NOCS and mask for every 6th frame, 250 ms late, with its depth's stamp (a
    hostile trial's robot): once frames match, the drops are said once at INFO; NOCS and mask
    stopping after 10 s is a WARN naming them once no frame has matched for 5 s."""
    messages = _slow_network(600, lambda k: 0.25, until=300)  # 20 s, NOCS and mask for 10
    steps = _steps(StampSynchronizer(3, queue_size=10), messages)
    matched_at = [m[2] for m, st in zip(messages, steps) if st.sets]
    assert len(matched_at) == 50 and matched_at[-1] < 10.3
    # Five of six depth images never match: dropped as unmatched, or from the full queue while
    # their frame's NOCS is on its way; after 10 s every depth image goes from the full queue.
    assert sum((st.dropped for st in steps), Counter()) == {"sync_queue_full": 442,
                                                            "sync_unmatched": 98}
    said = [(m[2], lv, key) for m, st in zip(messages, steps) for lv, key, _ in st.log]
    assert [(lv, key) for _, lv, key in said if lv == "info"] == [
        ("info", "sync_flowing_queue_full"), ("info", "sync_flowing_unmatched")]
    warns = [(t, key) for t, lv, key in said if lv == "warn"]
    assert warns and min(t for t, _ in warns) > matched_at[-1] + FLOWING_SECONDS
    assert {key for _, key in warns} == {"sync_queue_full"}
    assert "nothing from nocs and mask" in _lines(steps, "warn")["sync_queue_full"]


def test_intake_reset_forgets_that_frames_were_flowing():
    """After ~/reset (or a jump) no frame has matched since: the depth images the queue then
    drops are a WARN at once, not the flow the INFO line described before the reset."""
    intake = Intake(StampSynchronizer(3, queue_size=10), INPUT_NAMES)
    steps = _steps(None, _slow_network(120, lambda k: 0.25), intake)
    assert "sync_flowing_queue_full" in _lines(steps, "info")
    intake.reset()
    later = [(0, (200 + k) * FRAME_DT, 4.1 + k / 30) for k in range(12)]
    after = _steps(None, later, intake)
    assert "sync_queue_full" in _lines(after, "warn") and not _lines(after, "info")


# ----- one frame's messages to its estimate


def test_estimate_frame_is_the_core_estimate_of_the_images_and_names_what_it_refuses():
    import numpy as np
    from sensor_msgs.msg import CameraInfo

    from fcop_ros.core import estimate_focal
    from fcop_ros.ros.params import defaults, estimator_options
    from fcop_ros.synthetic.scenes import camera_frame
    from msg_adapters import depth_to_image, header_from_ns, mask_to_image, nocs_to_image

    fr, head = camera_frame(4), header_from_ns(1, "cam")
    msgs = (depth_to_image(fr.depth, "32FC1", head), nocs_to_image(fr.nocs, "32FC3", head),
            mask_to_image(fr.mask, "mono8", head))
    p, opts = defaults(), estimator_options(defaults())
    got = estimate_frame(msgs, p, None, opts, np.random.default_rng(3))
    h, w = fr.depth.shape
    seed = int(np.random.default_rng(3).integers(2**31))
    want = estimate_focal(fr.depth.astype(np.float32), fr.nocs.astype(np.float32), fr.mask,
                          ((w - 1) / 2, (h - 1) / 2), options=opts, poses=False, seed=seed,
                          principal_point_std=(0.0075 * w, 0.0075 * h))  # the centre assumed
    assert got.image_size == (w, h) and got.focal == pytest.approx(want.focal, rel=1e-9)
    assert abs(got.focal / 600.0 - 1) < 0.01

    small = mask_to_image(fr.mask[:-2], "mono8", head)
    wrong = depth_to_image(fr.depth, "32FC1", head)
    wrong.encoding = "rgb8"
    other = CameraInfo(width=w // 2, height=h // 2)
    cases = [((msgs[0], msgs[1], small), None, "size_mismatch"),
             ((wrong, msgs[1], msgs[2]), None, "bad_encoding"),
             (msgs, other, "camera_info_size_mismatch")]
    rng = np.random.default_rng(0)
    for frame_msgs, info, reason in cases:
        with pytest.raises(Refused) as refused:
            estimate_frame(frame_msgs, p, info, opts, rng)
        assert refused.value.reason == reason and str(refused.value)
    assert rng.integers(2**31) == np.random.default_rng(0).integers(2**31)  # no draw spent


# ----- the one-slot worker


class _Gated:
    """A handler that records what it gets and holds each item until released."""

    def __init__(self):
        self.got, self.go, self.started = [], threading.Event(), threading.Event()

    def __call__(self, item, generation):
        self.started.set()
        assert self.go.wait(10)
        self.got.append((item, generation))


def _wait(cond, timeout=10.0):
    done = threading.Event()
    for _ in range(int(timeout / 0.01)):
        if cond():
            return True
        done.wait(0.01)
    return cond()


def test_worker_skips_to_the_newest_item_and_counts_replacements():
    handler = _Gated()
    w = LatestSlotWorker(handler, on_error=lambda item, exc: None)
    w.start()
    try:
        assert not w.put(1)
        assert handler.started.wait(10) and w.busy_since is not None and not w.idle()
        replaced = [w.put(k) for k in (2, 3, 4)]
        assert replaced == [
            False,
            True,
            True,
        ]  # 2 waited, then 3 and 4 each replaced the waiting one
        handler.go.set()
        assert _wait(lambda: w.idle() and w.processed == 2)
        assert [item for item, _ in handler.got] == [1, 4]
        state = w.state()
        assert state.busy_since is None and state.last_done is not None and not state.waiting
    finally:
        w.stop()


def test_worker_clear_drops_the_waiting_item_and_starts_a_new_generation():
    handler = _Gated()
    w = LatestSlotWorker(handler, on_error=lambda item, exc: None)
    w.start()
    try:
        w.put("a")
        assert handler.started.wait(10)
        w.put("b")
        w.clear()
        assert w.generation == 1 and w.state().waiting is False
        w.put("c")
        handler.go.set()
        assert _wait(lambda: w.idle() and w.processed == 2)
        assert handler.got == [("a", 0), ("c", 1)]  # "a" was taken before the clear: generation 0
    finally:
        w.stop()


def test_worker_survives_a_failing_item_and_reports_it():
    errors = []

    def handle(item, generation):
        if item == "bad":
            raise ValueError("broken frame")

    w = LatestSlotWorker(handle, on_error=lambda item, exc: errors.append((item, str(exc))))
    w.start()
    try:
        w.put("bad")
        assert _wait(lambda: w.processed == 1)
        w.put("good")
        assert _wait(lambda: w.processed == 2 and w.idle())
        assert errors == [("bad", "broken frame")]
    finally:
        w.stop()
    assert not w._thread.is_alive()


def test_worker_runs_before_once_ahead_of_the_first_item():
    order = []
    warmed = threading.Event()

    def before():
        assert warmed.wait(10)  # items put meanwhile wait in the slot
        order.append("before")

    w = LatestSlotWorker(lambda item, g: order.append(item), on_error=lambda item, exc: None,
                         before=before)
    w.start()
    try:
        w.put(1)
        w.put(2)
        warmed.set()
        assert _wait(lambda: w.processed == 1 and w.idle())
        w.put(3)
        assert _wait(lambda: w.processed == 2 and w.idle())
        assert order == ["before", 2, 3]
    finally:
        w.stop()


# ----- the diagnostics builder


def _reading(**kw):
    base = {
        "now": 10.0,
        "window_estimate": WindowEstimate(600.0, std_rel=0.01, support=500, frames=5),
        "publishable": True,
        "window_fill": "5/30",
        "max_uncertainty": 0.05,
        "max_estimate_age": 2.0,
        "matched": 20,
        "processed": 20,
        "skipped": 0,
        "sync_dropped": 0,
        "camera_info_published": 20,
        "processing_ms": (10.0, 30.0, 20.0),
    }
    base.update(kw)
    return DiagnosticsInput(**base)


QUIET = Rates(span=5.0, matched=150, processed=150, skipped=0)


def test_diagnostics_ok_reports_the_estimate_and_timing():
    level, message, values = status_fields(_reading(dropped={"no_evidence": 2}), QUIET)
    assert level == DiagnosticStatus.OK and message == "focal 600.0 px"
    assert (
        values["focal_px"] == "600.000"
        and values["std_rel"] == "0.01000"
        and values["support_votes"] == "500"
    )
    assert values["frame_rate_hz"] == "30.00" and values["processing_ms_median"] == "20.00"
    assert values["processing_ms_max"] == "30.00" and values["dropped_no_evidence"] == "2"


def test_diagnostics_leave_the_timing_blank_before_any_frame():
    """No frame estimated yet: the processing times are blank, as the focal length and the age
    are, not 0.00 ms (a time nothing measured)."""
    idle = _reading(window_estimate=WindowEstimate(None, reason="no frames"), publishable=False,
                    processed=0, matched=0, camera_info_published=0, processing_ms=())
    _, _, values = status_fields(idle, Rates(span=5.0, matched=0, processed=0, skipped=0))
    assert values["processing_ms_median"] == values["processing_ms_max"] == ""
    assert values["focal_px"] == values["std_rel"] == ""


@pytest.mark.parametrize(
    "reading, rates, level, words",
    [
        (
            {"busy_for": 3.0, "age": 3.5},
            QUIET,
            DiagnosticStatus.ERROR,
            "estimator stalled: busy with one frame for 3.0 s",
        ),
        (
            {"window_estimate": WindowEstimate(None, reason="no frames")},
            QUIET,
            DiagnosticStatus.WARN,
            "no focal estimate yet: no frames",
        ),
        (
            {"window_estimate": WindowEstimate(None, reason="0 frames with focal evidence"),
             "last_reason": "NOCS channel 2 is 0.500 on every object"},
            QUIET,
            DiagnosticStatus.WARN,
            "no focal estimate yet: 0 frames with focal evidence; the newest frame: NOCS channel",
        ),
        (
            {"last_reason": "NOCS outside [0, 1]"},
            Rates(5.0, 150, 150, 0, 150, 120),
            DiagnosticStatus.WARN,
            "focal 600.0 px from earlier frames: 120 of the 150 frames estimated in the last "
            "5.0 s gave no focal (the newest: NOCS outside [0, 1])",
        ),
        (
            {"window_estimate": WindowEstimate(None, reason="no frames"), "warming_up": True},
            QUIET,
            DiagnosticStatus.WARN,
            "no focal estimate yet: the estimator is preparing its kernels",
        ),
        (
            {"publishable": False, "window_estimate": WindowEstimate(600.0, std_rel=0.2)},
            QUIET,
            DiagnosticStatus.WARN,
            "held back: std_rel 0.2000 above max_uncertainty 0.05",
        ),
        (
            {"publishable": False, "focal_range": (700.0, 2000.0)},
            QUIET,
            DiagnosticStatus.WARN,
            "focal 600.0 px held back: outside focal_range [700, 2000]",
        ),
        (
            {"no_camera_info": "camera_info_in is 640x480, the images are 320x240"},
            QUIET,
            DiagnosticStatus.WARN,
            "focal 600.0 px held back: no CameraInfo: camera_info_in is 640x480, the images are "
            "320x240",
        ),  # a new user's trial: no CameraInfo went out, diagnostics said OK
        (
            {},
            Rates(5.0, 150, 40, 110),
            DiagnosticStatus.WARN,
            "estimator behind: skipped 110 of 150 frames",
        ),
        (
            {},
            Rates(5.0, 0, 0, 0, answered=150),
            DiagnosticStatus.WARN,
            "150 depth images in the last 5.0 s but no matched depth, NOCS and mask set",
        ),  # a reviewer stopped the NOCS topic: CameraInfo went on, diagnostics said OK
        (
            {"window_estimate": WindowEstimate(None, reason="no frames yet"), "processed": 0,
             "matched": 0,
             "sync_dropped": 166, "dropped": {"sync_unmatched": 166}},
            Rates(5.0, 0, 0, 0),
            DiagnosticStatus.WARN,
            "no focal estimate yet: no frames yet; no depth, NOCS and mask set has matched: 166 "
            "messages dropped as unmatched: the inputs' stamps differ (exact sync needs equal "
            "stamps; sync_mode approximate matches within sync_slop)",
        ),  # a hostile trial: NOCS and mask stamped 3 and 6 ms after depth; no hint before
        (
            {"window_estimate": WindowEstimate(None, reason="window reset"), "matched": 0,
             "sync_dropped": 399, "dropped": {"sync_queue_full": 399}},
            Rates(5.0, 0, 0, 0),
            DiagnosticStatus.WARN,
            "399 messages dropped from full queues: an input is stamped further behind the "
            "others than queue_size messages (raise queue_size to cover its delay times the "
            "others' rate)",
        ),  # the same trial: NOCS and mask 300 ms late at 30 Hz, queue_size 5
        (
            {"window_estimate": WindowEstimate(None, reason="no frames yet"), "processed": 0,
             "matched": 0,
             "sync_dropped": 399, "dropped": {"sync_queue_full": 399},
             "queue_advice": "nocs comes 250 ms after the depth of its stamp, at 30 Hz: "
                             "queue_size must be above 7.5"},
            Rates(5.0, 0, 0, 0),
            DiagnosticStatus.WARN,
            "behind the others than queue_size messages (nocs comes 250 ms after the depth of "
            "its stamp, at 30 Hz: queue_size must be above 7.5)",
        ),  # the re-run trial: the rule, but no number
        (
            {"sync_dropped": 900, "dropped": {"sync_queue_full": 800, "sync_unmatched": 100},
             "input_ages": (("depth", 0.01), ("nocs", 6.2), ("mask", 6.2))},
            Rates(5.0, 0, 0, 0, answered=150),
            DiagnosticStatus.WARN,
            "no matched depth, NOCS and mask set (no nocs message for 6.2 s and no mask message "
            "for 6.2 s (silent, or their topics remapped elsewhere?))",
        ),  # a hostile trial: a NOCS network at 5 Hz stopped; the lifetime drops (of a healthy
        # slower input) said "raise queue_size"
        (
            {"age": 20.3, "input_ages": (("depth", 20.3), ("nocs", 20.4), ("mask", 20.4))},
            Rates(5.0, 0, 0, 0),
            DiagnosticStatus.WARN,
            "focal 600.0 px from an estimate 20.3 s old: no input for 20.3 s (camera stopped, "
            "or topics remapped?)",
        ),  # the same trial: every input stopped, diagnostics said OK for 20 s
        (
            {"window_estimate": WindowEstimate(None, reason="no frames yet"), "processed": 0,
             "input_ages": (("depth", 0.02), ("nocs", None), ("mask", None))},
            Rates(5.0, 0, 0, 0, answered=150),
            DiagnosticStatus.WARN,
            "no focal estimate yet: no frames yet",
        ),  # never heard from nocs and mask: the depth came only now, not silent yet
        (
            {"window_estimate": WindowEstimate(None, reason="no frames yet"), "processed": 0,
             "matched": 0,
             "sync_dropped": 40, "dropped": {"sync_queue_full": 40},
             "input_ages": (("depth", 0.01), ("nocs", 0.01), ("mask", None)),
             "since_first_input": 12.0},
            Rates(5.0, 0, 0, 0, answered=150),
            DiagnosticStatus.WARN,
            "no focal estimate yet: no frames yet; no depth, NOCS and mask set has matched: no "
            "mask message for 12.0 s (silent, or its topic remapped elsewhere?)",
        ),  # a hostile trial: the mask never sent, and for 12 s the advice was queue_size
        (
            {"window_estimate": WindowEstimate(None, reason="no frames yet"), "processed": 0,
             "input_ages": (("depth", 8.0), ("nocs", 8.0), ("mask", 8.0)),
             "since_first_input": 9.0},
            Rates(5.0, 0, 0, 0),
            DiagnosticStatus.WARN,
            "no focal estimate yet: no frames yet; no input for 8.0 s (camera stopped, or "
            "topics remapped?)",
        ),  # the same trial: frames without evidence, then the camera stopped: never said
        (
            {"input_ages": (("depth", 0.01), ("nocs", 0.15), ("mask", 0.15))},
            Rates(5.0, 25, 25, 0, answered=150, inputs=(150, 25, 25)),
            DiagnosticStatus.OK,
            "focal 600.0 px",
        ),  # a slower NOCS network, matching
        (
            {"input_ages": (("depth", 0.01), ("nocs", 0.15), ("mask", 0.15)),
             "sync_dropped": 900, "dropped": {"sync_queue_full": 700, "sync_unmatched": 200}},
            Rates(5.0, 7, 7, 0, answered=150, inputs=(150, 25, 25)),
            DiagnosticStatus.WARN,
            "focal 600.0 px from few frames: only 7 of the 25 nocs messages in the last 5.0 s "
            "made a frame (700 messages dropped from full queues",
        ),  # the re-run trial: NOCS 265 ms late with queue_size 8; 33 of 125 matched, OK said
        (
            {"sync_dropped": 40, "dropped": {"sync_unmatched": 40}},
            Rates(5.0, 0, 0, 0, answered=150),
            DiagnosticStatus.WARN,
            "no matched depth, NOCS and mask set (40 messages dropped as unmatched: the inputs' "
            "stamps differ",
        ),  # with an estimate, the same hint instead of blaming a silent topic
        (
            {"input_ages": (("depth", 0.03), ("nocs", 0.03), ("mask", 0.03)),
             "sync_dropped": 84, "dropped": {"sync_unmatched": 84}},
            Rates(5.0, 20, 20, 0, answered=44, inputs=(44, 44, 44)),
            DiagnosticStatus.WARN,
            "(84 messages dropped as unmatched while 20 frames matched: no message of their "
            "stamps came on the other inputs (lost in transport? large images between "
            "processes need config/fastdds_large_images.xml",
        ),  # a hostile trial: equal stamps, 40% of each input lost; 'stamps differ' before
        (
            {"busy_for": 1.0},
            QUIET,
            DiagnosticStatus.OK,
            "focal 600.0 px",
        ),  # busy, within max_estimate_age
        (
            {"input_ages": (("depth", 0.1), ("nocs", 0.1), ("mask", 0.1)),
             "sync_dropped": 45, "dropped": {"sync_duplicate": 45}},
            Rates(5.0, 1, 1, 0, answered=16, inputs=(16, 16, 16), drops={"sync_duplicate": 45}),
            DiagnosticStatus.WARN,
            "only 1 of the 16 depth messages in the last 5.0 s made a frame (45 messages "
            "dropped as duplicates: a stamp its input had already sent (is the driver stamping",
        ),  # a hostile review: every stamp 0; the hint asked whether NOCS or mask was silent
        (
            {"input_ages": (("depth", 0.1), ("nocs", 0.1), ("mask", 0.1)),
             "sync_dropped": 60, "dropped": {"sync_queue_full": 50, "sync_duplicate": 10},
             "queue_advice": "raise queue_size to at least 9: nocs comes 1895 ms after"},
            Rates(5.0, 1, 1, 0, answered=16, inputs=(16, 16, 16), drops={"sync_duplicate": 10}),
            DiagnosticStatus.WARN,
            "(10 messages dropped as duplicates",
        ),  # the same review: a NOCS outage's queue drops long past, judged by recent drops
    ],
)
def test_diagnostics_levels(reading, rates, level, words):
    got_level, message, _ = status_fields(_reading(**reading), rates)
    assert got_level == level and words in message, message


def test_rate_window_counts_recent_drops_by_reason():
    rw = RateWindow(5.0, start=0.0)
    assert rw.add(1.0, 0, 0, 0, drops={"sync_queue_full": 50}).drops == {"sync_queue_full": 50}
    rw.add(4.0, 0, 0, 0, drops={"sync_queue_full": 50})
    r = rw.add(7.0, 0, 0, 0, drops={"sync_queue_full": 50, "sync_duplicate": 12})
    assert r.drops == {"sync_duplicate": 12}  # the queue drops are older than the span


def test_rate_window_spans_back_to_the_newest_reading_at_least_five_seconds_old():
    rw = RateWindow(5.0)
    assert rw.add(0.0, 0, 0, 0).frame_hz == 0.0  # one reading: no span
    rw.add(3.0, 90, 60, 30)
    r = rw.add(6.0, 180, 120, 60)  # 0 s is the newest reading at least 5 s old
    assert r.span == 6.0 and r.frame_hz == 30.0 and r.estimator_hz == 20.0 and r.skipped == 60
    r = rw.add(9.0, 360, 150, 60, 400)  # now 3 s is: the reading at 0 s is forgotten
    assert r.span == 6.0 and r.matched == 270 and r.processed == 90 and r.skipped == 30
    assert r.answered == 400
    # From the node's start, the first reading has rates (it read 0.00 Hz before); the second
    # is taken against the first, as before.
    rw = RateWindow(5.0, start=10.0)
    assert rw.add(11.0, 30, 30, 0, inputs=(30, 5, 5)).frame_hz == 30.0
    r = rw.add(12.0, 90, 90, 0, inputs=(90, 15, 15))
    assert r.frame_hz == 60.0 and r.inputs == (60, 10, 10)  # each input's messages, alike


# ----- the DDS environment


def test_keep_on_this_machine_sets_only_what_is_unset():
    from fcop_ros.ros.dds import (keep_on_this_machine, profile_env_vars, ros_distro,
                                  use_large_image_profile)

    env = keep_on_this_machine({"ROS_DOMAIN_ID": "7"}, domain_id=99)
    assert env["ROS_DOMAIN_ID"] == "7" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    # ... except a developer's ROS_LOCALHOST_ONLY, which from Jazzy overrides the profile
    env = keep_on_this_machine({"ROS_LOCALHOST_ONLY": "1"})
    assert ("ROS_LOCALHOST_ONLY" in env) == (ros_distro() in ("humble", "iron"))
    assert keep_on_this_machine({}, domain_id=99)["ROS_DOMAIN_ID"] == "99"
    env = use_large_image_profile({})
    assert set(env) == set(profile_env_vars()) and all(v.endswith(".xml") for v in env.values())


def test_isolated_keeps_a_run_off_the_shells_graph_and_restores_the_shell():
    from fcop_ros.ros.dds import isolated, ros_distro

    shell = {"ROS_DOMAIN_ID": "0", "ROS_LOCALHOST_ONLY": "1", "ROS_STATIC_PEERS": "10.0.0.2"}
    env = dict(shell)
    with isolated(env) as domain:
        assert env["ROS_DOMAIN_ID"] == str(domain) and 200 <= domain <= 232
        if ros_distro() not in ("humble", "iron"):
            assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "OFF"
            assert "ROS_LOCALHOST_ONLY" not in env and "ROS_STATIC_PEERS" not in env
    assert env == shell


# ----- the calibration file


def test_calibration_file_round_trips_through_yaml(tmp_path):
    import yaml

    from fcop_ros.ros.calibration import write_calibration
    from msg_adapters import camera_info

    info = camera_info(612.5, 319.5, 239.5, 640, 480)
    path = tmp_path / "deep" / "cam.yaml"
    write_calibration(str(path), info, "front")
    doc = yaml.safe_load(path.read_text())
    assert doc["camera_name"] == "front" and (doc["image_width"], doc["image_height"]) == (
        640,
        480,
    )
    assert doc["camera_matrix"]["data"] == [612.5, 0.0, 319.5, 0.0, 612.5, 239.5, 0.0, 0.0, 1.0]
    assert doc["distortion_model"] == "plumb_bob" and len(doc["projection_matrix"]["data"]) == 12
    assert [p.name for p in path.parent.iterdir()] == ["cam.yaml"]  # no temporary file left


def test_a_failed_calibration_write_leaves_no_temporary_file(tmp_path):
    """A calibration_file that is a directory: the rename fails (OSError, which the service
    answers with) and the temporary file beside it goes (before, it stayed)."""
    import pytest

    from fcop_ros.ros.calibration import write_calibration
    from msg_adapters import camera_info

    (tmp_path / "isdir.yaml").mkdir()
    with pytest.raises(OSError):
        write_calibration(str(tmp_path / "isdir.yaml"), camera_info(600.0, 320, 240, 640, 480),
                          "front")
    assert [p.name for p in tmp_path.iterdir()] == ["isdir.yaml"]


def test_save_calibration_says_where_and_what_or_why_not(tmp_path, monkeypatch):
    """The service's outcome without a node: the path (calibration_file, else
    camera_info_manager's default under $HOME), the message, and a refusal to write."""
    from fcop_ros.ros.calibration import calibration_path, save_calibration
    from msg_adapters import camera_info

    monkeypatch.setenv("HOME", str(tmp_path))
    assert calibration_path("", "front") == str(tmp_path / ".ros" / "camera_info" / "front.yaml")
    assert calibration_path("~/x/cam.yaml", "front") == str(tmp_path / "x" / "cam.yaml")
    info = camera_info(612.5, 319.5, 239.5, 640, 480)
    ok, message = save_calibration(info, 0.0123, str(tmp_path / "c.yaml"), "front")
    assert ok and message == f"saved focal 612.50 px (std_rel 0.0123) to {tmp_path / 'c.yaml'}"
    (tmp_path / "file").write_text("")
    ok, message = save_calibration(info, 0.0123, str(tmp_path / "file" / "c.yaml"), "front")
    assert not ok and message.startswith(f"cannot write {tmp_path / 'file' / 'c.yaml'}: ")


# ----- the intrinsics every CameraInfo carries


def _cam_in(w=640, h=480, cx=0.0, cy=0.0, model="", d=(), r=(1, 0, 0, 0, 1, 0, 0, 0, 1),
            binning=(0, 0), roi=None):
    from sensor_msgs.msg import CameraInfo, RegionOfInterest

    msg = CameraInfo(width=w, height=h, distortion_model=model, d=list(d))
    msg.k[2], msg.k[5] = cx, cy
    msg.r = [float(v) for v in r]
    msg.binning_x, msg.binning_y = binning
    if roi is not None:
        msg.roi = RegionOfInterest(x_offset=roi[0], y_offset=roi[1], width=roi[2], height=roi[3])
    return msg


def test_camera_info_in_binning_and_roi_describe_smaller_images():
    """REP-104: width, height, K and P are the full sensor's; the images are the ROI, binned. A
    driver binning 2x2 a 1280x960 sensor sends 640x480 images whose principal point is half of
    K's; one cropping a 640x480 ROI at (320, 240) moves it by the offset (image_geometry's
    arithmetic). Before 25 Nov 2026 both had every frame dropped as another size."""
    from fcop_ros.ros.intrinsics import IntrinsicsRefused, intrinsics

    p = {"principal_point_x": -1.0, "principal_point_y": -1.0}
    binned = intrinsics(p, _cam_in(1280, 960, cx=639.0, cy=479.0, binning=(2, 2)), 640, 480)
    assert (binned.cx, binned.cy, binned.assumed) == (319.5, 239.5, (False, False))
    crop = _cam_in(1280, 960, cx=639.0, cy=479.0, roi=(320, 240, 640, 480))
    assert (intrinsics(p, crop, 640, 480).cx, intrinsics(p, crop, 640, 480).cy) == (319.0, 239.0)
    both = _cam_in(1280, 960, cx=639.0, cy=479.0, binning=(2, 2), roi=(320, 240, 640, 480))
    assert (intrinsics(p, both, 320, 240).cx, intrinsics(p, both, 320, 240).cy) == (159.5, 119.5)
    with pytest.raises(IntrinsicsRefused, match="images 320x240 after its ROI and binning"):
        intrinsics(p, both, 640, 480)



def test_a_calibration_for_the_driver_is_at_its_full_resolution():
    """What ~/save_calibration stores and sends: the images' CameraInfo taken back through
    camera_info_in's ROI and binning (K, P and Tx times the binning, the principal point plus
    the ROI offset, the sensor's size, no binning or ROI); unchanged for a driver that neither
    bins nor crops, and without camera_info_in."""
    from fcop_ros.ros.intrinsics import at_full_resolution, camera_info_with, intrinsics

    p = {"principal_point_x": -1.0, "principal_point_y": -1.0}
    both = _cam_in(1280, 960, cx=639.0, cy=479.0, binning=(2, 2), roi=(320, 240, 640, 480))
    # The second camera of a stereo pair, 6 cm apart: P[0, 3] = -0.06 fx.
    both.p = [1200.0, 0.0, 639.0, -72.0, 0.0, 1200.0, 479.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    info = camera_info_with(300.0, intrinsics(p, both, 320, 240), 320, 240, None)
    assert (info.k[2], info.k[5], info.p[3]) == (159.5, 119.5, pytest.approx(-18.0))
    full = at_full_resolution(info, both)
    assert (full.width, full.height, full.binning_x, full.binning_y) == (1280, 960, 0, 0)
    assert (full.roi.width, full.roi.height, full.roi.x_offset) == (0, 0, 0)
    assert list(full.k) == [600.0, 0.0, 639.0, 0.0, 600.0, 479.0, 0.0, 0.0, 1.0]
    assert list(full.p) == pytest.approx([600.0, 0, 639.0, -36.0, 0, 600.0, 479.0, 0, 0, 0, 1, 0])
    assert (info.width, info.k[0]) == (320, 300.0)  # the images' own is left as it was
    plain = _cam_in(640, 480, cx=300.0, cy=250.0)
    same = camera_info_with(300.0, intrinsics(p, plain, 640, 480), 640, 480, None)
    assert at_full_resolution(same, plain) is same and at_full_resolution(same, None) is same


def test_principal_point_per_axis_from_parameter_then_camera_info_in_then_centre():
    from fcop_ros.ros.intrinsics import intrinsics

    p = {"principal_point_x": -1.0, "principal_point_y": -1.0}
    assert intrinsics(p, None, 640, 480) == intrinsics(p, _cam_in(), 640, 480)
    assert (intrinsics(p, None, 640, 480).cx, intrinsics(p, None, 640, 480).cy) == (319.5, 239.5)
    got = intrinsics(p, _cam_in(cx=300.0, cy=250.0), 640, 480)
    assert (got.cx, got.cy, got.tx_per_f) == (300.0, 250.0, 0.0)
    got = intrinsics(dict(p, principal_point_y=200.0), _cam_in(cx=300.0, cy=250.0), 640, 480)
    assert (got.cx, got.cy) == (300.0, 200.0)
    # Only the image centre is an assumption, which the reported uncertainty pays for.
    assert intrinsics(p, None, 640, 480).assumed == (True, True)
    assert intrinsics(dict(p, principal_point_y=200.0), None, 640, 480).assumed == (True, False)
    assert intrinsics(p, _cam_in(cx=300.0, cy=250.0), 640, 480).assumed == (False, False)


@pytest.mark.parametrize("params, cam, reason", [
    ({"principal_point_x": 700.0, "principal_point_y": -1.0}, None, "principal_point_outside"),
    ({"principal_point_x": -1.0, "principal_point_y": -1.0}, _cam_in(320, 240),
     "camera_info_size_mismatch"),
    ({"principal_point_x": -1.0, "principal_point_y": -1.0}, _cam_in(1280, 960, binning=(2, 1)),
     "camera_info_binning_unequal"),
])
def test_intrinsics_refused_name_their_drop_counter(params, cam, reason):
    from fcop_ros.ros.intrinsics import IntrinsicsRefused, intrinsics

    with pytest.raises(IntrinsicsRefused) as err:
        intrinsics(params, cam, 640, 480)
    assert err.value.reason == reason and "640x480" in str(err.value)


def test_camera_info_describes_the_rectified_camera_of_camera_info_in():
    """REP-104: K, D and R describe the raw camera, P the rectified one, which fcop_node sees.
    Its principal point comes from P (K's when P is unset), D is zero, R the identity, and a
    stereo camera's P[0, 3] / P[0, 0] (minus the baseline) is kept at the new focal."""
    from fcop_ros.ros.intrinsics import camera_info_with, intrinsics, raw_camera

    p = {"principal_point_x": -1.0, "principal_point_y": -1.0}
    tilted = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    cam = _cam_in(cx=310.0, cy=230.0, model="plumb_bob", d=(0.1, -0.2, 0, 0, 0), r=tilted)
    cam.p = [480.0, 0.0, 305.5, -480.0 * 0.12, 0.0, 480.0, 233.5, 0.0, 0.0, 0.0, 1.0, 0.0]
    info = camera_info_with(600.0, intrinsics(p, cam, 640, 480), 640, 480, None)
    assert list(info.k) == [600.0, 0.0, 305.5, 0.0, 600.0, 233.5, 0.0, 0.0, 1.0]
    assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5
    assert list(info.r) == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    assert list(info.p) == pytest.approx(
        [600.0, 0.0, 305.5, -600.0 * 0.12, 0.0, 600.0, 233.5, 0.0, 0.0, 0.0, 1.0, 0.0])
    assert raw_camera(cam) == ("distortion plumb_bob D=[0.1, -0.2, 0.0, 0.0, 0.0] and "
                               "rectification R=[0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]")
    k_only = _cam_in(cx=310.0, cy=230.0, model="plumb_bob", d=(0,) * 5, r=(0,) * 9)
    got = intrinsics(p, k_only, 640, 480)  # a driver that fills only K: K's principal point
    assert (got.cx, got.cy, got.tx_per_f) == (310.0, 230.0, 0.0) and raw_camera(k_only) == ""


# ----- the publish gate


@pytest.mark.parametrize("window, words", [
    (WindowEstimate(None, reason="no frames yet"), "no focal estimate yet: no frames yet"),
    (WindowEstimate(600.0, std_rel=None), "std_rel unknown above max_uncertainty 0.05"),
    (WindowEstimate(600.0, std_rel=0.06), "focal 600.0 px held back: std_rel 0.0600 above"),
    (WindowEstimate(650.0, std_rel=0.01), "focal 650.0 px held back: outside focal_range "
                                           "[300, 640]"),
    (WindowEstimate(600.0, std_rel=0.05), ""),  # at max_uncertainty: it goes out
    (WindowEstimate(640.0, std_rel=0.01), ""),  # at focal_max
])
def test_the_gate_says_why_a_focal_is_held_back(window, words):
    from fcop_ros.ros.gate import held_back

    why = held_back(window, 0.05, (300.0, 640.0))
    assert words in why if words else why == ""


def test_camera_info_output_answers_each_depth_stamp_once_and_the_owed_one_later():
    """The CameraInfo side without a node: a depth image before any estimate is owed its
    CameraInfo, which the worker's frame pays once publishable; one of another size is not
    answered; the latest publication carries the newest frame's objects."""
    from types import SimpleNamespace as NS

    from fcop_ros.ros.camera_info_output import CameraInfoOutput
    from fcop_ros.ros.intrinsics import IntrinsicsRefused
    from fcop_ros.ros.tracker import Publishable

    sent = []

    def build(focal, w, h, header):
        if getattr(header, "refuse", False):
            raise IntrinsicsRefused("principal_point_outside", "off the image")
        return NS(k=[focal, 0, w / 2, 0, focal, h / 2, 0, 0, 1], width=w, height=h)

    out = CameraInfoOutput(sent.append, build)
    ready = Publishable(600.0, 0.01, 640, 480, WindowEstimate(600.0, 0.01, 300, 4, 4), "cam")
    h = NS(frame_id="cam")
    depth = NS(width=640, height=480, header=h)
    out.answer_depth(1, depth, lambda: None)  # before any estimate: owed
    assert sent == [] and out.latest is None
    out.answer_owed(1, h, ready)
    out.answer_owed(1, h, ready)  # paid once
    assert len(sent) == 1 and out.latest.stamp_ns == 1 and out.latest.frames == 4
    out.answer_depth(1, depth, lambda: ready)  # the same stamp again: answered already
    out.answer_depth(2, NS(width=320, height=240, header=h), lambda: ready)  # another size
    # Another camera frame: the window's focal is not this camera's (an audit: it answered).
    out.answer_depth(2, NS(width=640, height=480, header=NS(frame_id="other")), lambda: ready)
    out.answer_depth(3, NS(width=640, height=480, header=NS(frame_id="cam", refuse=True)),
                     lambda: ready)
    assert len(sent) == 1 and out.published == 1
    out.objects(1, ["pose"])
    assert out.latest.objects == ("pose",)
    out.answer_depth(4, depth, lambda: ready)
    out.answer_owed(2, h, ready)  # older than a stamp answered since: never out of order
    assert [s.width for s in sent] == [640, 640] and out.latest.objects == ("pose",)
    # A depth image arriving after a newer one is answered on arrival, as a driver's would be.
    out.answer_depth(3, depth, lambda: ready)
    assert len(sent) == 3 and out.latest.stamp_ns == 3
    out.withdraw()  # the gate closed on it: the node swapped its latched publisher
    assert out.latest is None and out.published == 3
    out.answer_depth(3, depth, lambda: ready)  # answered stamps stay answered
    assert len(sent) == 3
    out.clear()
    assert out.latest is None
    out.answer_depth(4, depth, lambda: ready)  # after a reset each stamp is answered anew
    assert len(sent) == 4 and out.latest.objects == ()


def test_ledger_counts_frames_without_a_focal_since_the_window_was_emptied():
    from types import SimpleNamespace as NS

    from fcop_ros.ros.frame_outcome import FrameOutcome
    from fcop_ros.ros.ledger import NodeLedger

    led = NodeLedger(keep=2)
    led.no_focal("bad_encoding", "dropped: " + "x" * 400)
    assert len(led.newest_refusal) == 300 and led.dropped == {"bad_encoding": 1}
    kept = FrameOutcome(Counter(), Counter({"mirrored_nocs": 1}), (), True)
    for focal in (None, 600.0, 601.0):
        led.estimated(NS(focal=focal, reason="few votes"), kept, 0.01)
    assert (led.no_focal_frames, led.since_empty, led.newest_refusal) == (2, 4, "")
    assert led.warnings == {"mirrored_nocs": 3} and len(led.processing_seconds) == 2
    led.window_emptied()
    assert led.since_empty == 0 and led.no_focal_frames == 2


def test_health_news_says_each_problem_once_and_its_end():
    from fcop_ros.ros.diagnostics import HealthNews

    news, WARN, ERROR = HealthNews(), DiagnosticStatus.WARN, DiagnosticStatus.ERROR
    assert news(WARN, "no focal estimate yet: no frames yet") is None  # the start: no news
    said = news(WARN, "no focal estimate yet: no frames yet; no depth message for 3.0 s")
    assert said == (WARN, "no focal estimate yet: no frames yet; no depth message for 3.0 s")
    assert news(WARN, "no focal estimate yet: no frames yet; no depth message for 9.5 s") is None
    assert news(ERROR, "estimator stalled: busy with one frame for 4.0 s")[0] == ERROR
    assert news(DiagnosticStatus.OK, "focal 600.0 px") == (
        DiagnosticStatus.OK, "healthy again: focal 600.0 px")
    assert news(DiagnosticStatus.OK, "focal 600.0 px") is None


# ----- shutting a context down


def _raced_once(ctx):
    """A ``try_shutdown`` for ``ctx`` whose first call meets a signal's shutdown between its
    check and its own (the second then raises what that distribution's rcl raises)."""
    calls = []

    def raced():
        if not calls:
            calls.append(1)
            ctx.handle.shutdown()  # the signal thread's, after try_shutdown found the context ok
            ctx.handle.shutdown()  # try_shutdown's own
    return raced


def test_shut_down_takes_a_context_that_a_signal_shut_down_under_it_as_done(monkeypatch):
    """Jazzy's signal handler shuts contexts down from its own thread without rclpy's lock.
    When that fell between ``try_shutdown``'s check and its shutdown, rcl raised
    "rcl_shutdown already called" and a clean Ctrl-C exited 1 with a traceback (CI on 2a67016,
    once; not seen in 15 runs of the Ctrl-C tests here). Here the two shutdowns come in that
    order. Any other failure, with the context still up, still raises."""
    import rclpy
    from rclpy.context import Context

    from fcop_ros.ros.spin import shut_down

    ctx = Context()
    rclpy.init(context=ctx)
    monkeypatch.setattr(ctx, "try_shutdown", _raced_once(ctx))
    shut_down(ctx)
    assert not ctx.ok()

    other = Context()
    rclpy.init(context=other)

    def fails():
        raise RuntimeError("failed to shutdown: something else")

    monkeypatch.setattr(other, "try_shutdown", fails)
    with pytest.raises(RuntimeError, match="something else"):
        shut_down(other)
    monkeypatch.undo()
    other.try_shutdown()


def test_shut_down_of_the_default_context_lets_rclpy_init_again(monkeypatch):
    """fcop_replay --play runs on rclpy's default context and may run twice in one process (the
    tests do). The first shut_down shut it down without letting rclpy replace it, and the
    second run's rclpy.init raised "Context.init() must only be called once" (CI on 1b54fca).
    Also after the race above."""
    import rclpy
    from rclpy.utilities import get_default_context

    from fcop_ros.ros.spin import shut_down

    for race in (False, True):
        rclpy.init()
        ctx = get_default_context()
        if race:
            monkeypatch.setattr(ctx, "try_shutdown", _raced_once(ctx))
        shut_down()
        assert not ctx.ok() and get_default_context() is not ctx, race
    rclpy.init()  # the one a third run makes
    shut_down()
