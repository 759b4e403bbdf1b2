"""fcop_replay --play: publish a bag's image topics with the recorded timing, and the recorded time
on /clock, as `ros2 bag play --clock` would, for a live node."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

from ..ros.dds import use_large_image_profile
from ..ros.sync import RESET_AFTER
from ..ros.topics import INPUTS
from .bagio import BagSource
from .cli import raise_ctrl_c
from .replay_base import (IMAGE_TYPE, ReplayError, check_distinct, check_not_empty,
                          check_topics)


@dataclass
class PlayResult:
    """What a --play run did: messages published, /clock messages, laps played to their end
    (with --loop), and the damage it met."""

    published: int = 0
    laps: int = 0
    clock: int = 0
    damaged: str = ""
    no_subscriber: tuple = ()  # topics still without a subscriber when the wait ended


def _wait_for_subscribers(node, pubs: dict, seconds: float, stop, say) -> tuple:
    """Spin ``node`` until every publisher of ``pubs`` ({topic: publisher}) has a subscriber,
    ``seconds`` pass or ``stop`` is set; say what it waits for and how it ended. Returns the
    topics still without a subscriber."""
    from rclpy.executors import SingleThreadedExecutor

    from ..ros.spin import spin_until

    def missing():
        return tuple(t for t, pub in pubs.items() if pub.get_subscription_count() == 0)

    if not missing():
        return ()
    start = time.monotonic()
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        # Said once the executor is whole: a signal that came while rclpy built it left a
        # half-made executor whose __del__ printed a traceback.
        say(f"waiting up to {seconds:g} s for a subscriber on each of {', '.join(missing())}")
        spin_until(executor, lambda: stop.is_set() or not missing(), seconds)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=1.0)
    left = missing()
    if left:
        say(f"no subscriber on {', '.join(left)} after {seconds:g} s: playing anyway")
    else:
        say(f"every topic has a subscriber (after {time.monotonic() - start:.2f} s)")
    return left


def _check_numbers(rate: float, clock_hz: float, wait_subscribers: float) -> None:
    """ReplayError for a number play cannot use: nan or infinity (a nan --clock-hz was taken
    and ticked at an undefined rate), or out of its range."""
    for option, value, positive in (("--rate", rate, True), ("--clock-hz", clock_hz, False),
                                    ("--wait-subscribers", wait_subscribers, False)):
        if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise ReplayError(f"{option} must be a finite number {'> 0' if positive else '>= 0'}"
                              f", got {value:g}")


def _too_short_to_loop(times: list) -> bool:
    """Whether depth images at bag times ``times`` (ns, at least one) span too little for a
    loop back to be told from jitter: the node's synchroniser needs three stamps more than
    ``RESET_AFTER`` back (see the README's sync section)."""
    return len(times) < 2 or times[-1] - times[0] <= RESET_AFTER * 1e9 + 2 * (times[1] - times[0])


def _readable(source: BagSource, topics):
    """The bag's messages up to the first damage (then ``source.damaged`` says what it was)."""
    it = source.messages(topics)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except Exception as exc:  # a damaged storage read through rosbags: stop here, say why
            raise_ctrl_c(exc)
            source.damaged = source.damaged or f"{type(exc).__name__}: {exc}"
            return
        yield item


def play(
    bag,
    image_topics,
    *,
    rate: float = 1.0,
    loop: bool = False,
    context=None,
    stop: threading.Event | None = None,
    qos_depth: int = 10,
    clock: bool = True,
    clock_hz: float = 40.0,
    wait_subscribers: float = 5.0,
    say=None,
) -> PlayResult:
    """Publish the bag's messages of ``image_topics`` (the depth, NOCS and mask topics, in that
    order: errors name them so) with the recorded timing scaled by ``rate``.

    With ``clock`` the bag's time goes out on /clock (rosgraph_msgs/Clock), as `ros2 bag play
    --clock` does: the recorded time of every message just before it, and in between at
    ``clock_hz`` (0: only at the messages), so nodes with use_sim_time follow the bag. ``context``
    is an initialised rclpy Context (default: the global one, initialised here); ``stop`` ends
    playback early. A damaged bag is played up to the damage (``PlayResult.damaged``); with
    ``loop``, over and over up to it, which ``say`` is told once.

    Before the first message it waits, spinning, up to ``wait_subscribers`` seconds (0: not at
    all) until each image topic has a subscriber, so a live node that is still being discovered
    does not lose the first frames; ``say`` (a function of one line) is told what it waits for
    and how the wait ended (``PlayResult.no_subscriber``: the topics still without one), and
    of an unreadable metadata.yaml whose .mcap files are played without it."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    from msg_adapters import time_from_ns

    from ..ros.spin import shut_down

    _check_numbers(rate, clock_hz, wait_subscribers)
    say = say or (lambda line: None)
    inputs = dict(zip(INPUTS, image_topics, strict=True))
    check_distinct(inputs)
    source = BagSource(bag)
    try:
        check_topics(source, {role: (t, IMAGE_TYPE) for role, t in inputs.items()})
        check_not_empty(source, inputs)
    except ReplayError:
        source.close()
        raise
    if source.metadata_problem:
        say(source.metadata_problem)
    own = context is None
    if own:
        use_large_image_profile()
        rclpy.init()
    node = Node("fcop_player", context=context)
    pubs = {t: node.create_publisher(Image, t, qos_depth) for t in image_topics}
    clock_pub = node.create_publisher(Clock, "/clock", 10) if clock else None
    stop = stop or threading.Event()
    result = PlayResult()
    last_clock = [None]

    def tick(ns: int) -> None:
        if last_clock[0] is not None and ns <= last_clock[0]:
            return
        msg = Clock()
        msg.clock = time_from_ns(ns)
        clock_pub.publish(msg)
        last_clock[0] = ns
        result.clock += 1

    def wait_until(due: float, start_wall: float, start_bag: int, ts: int) -> bool:
        """Sleep until ``due`` (monotonic), ticking /clock meanwhile; False when stopped."""
        period = 1.0 / clock_hz if clock_pub is not None and clock_hz > 0 else None
        next_tick = time.monotonic() + period if period else float("inf")
        while True:
            now = time.monotonic()
            if now >= due:
                return True
            # At most 0.1 s at a time: a signal rclpy took (its context shut down, no Python
            # KeyboardInterrupt when SIGINT was ignored at start) ends a long gap too.
            if stop.wait(min(due, next_tick, now + 0.1) - now):
                return False
            if not node.context.ok():
                raise KeyboardInterrupt
            now = time.monotonic()
            if now >= next_tick and now < due:
                tick(min(ts, start_bag + int((now - start_wall) * rate * 1e9)))
                next_tick += period * max(1, int((now - next_tick) / period) + 1)

    try:
        if wait_subscribers > 0:
            result.no_subscriber = _wait_for_subscribers(node, pubs, wait_subscribers, stop, say)
        depth_times: list = []  # the first lap's depth message times, to judge a loop
        while not stop.is_set():
            start_wall, start_bag, before = None, None, result.published
            last_clock[0] = None  # a loop starts the bag's time over, as rosbag2 does
            for topic, ts, raw in _readable(source, image_topics):
                if stop.is_set():
                    break
                if start_wall is None:
                    start_wall, start_bag = time.monotonic(), ts
                if topic == image_topics[0] and not result.laps:
                    depth_times.append(ts)
                if not wait_until(
                    start_wall + (ts - start_bag) * 1e-9 / rate, start_wall, start_bag, ts
                ):
                    break
                if clock_pub is not None:
                    tick(ts)
                pubs[topic].publish(raw)
                result.published += 1
            if loop and source.damaged and not result.damaged and not stop.is_set():
                say(f"bag damaged ({source.damaged}); looping over the "
                    f"{result.published - before} messages before the damage")
            result.damaged = source.damaged
            if not loop or start_wall is None:
                break
            if (not result.laps and depth_times and not stop.is_set()
                    and _too_short_to_loop(depth_times)):
                say(f"the bag's depth images span {(depth_times[-1] - depth_times[0]) / 1e9:.2f}"
                    " s: fcop_node takes a new lap's stamps for a loop only when they lie more "
                    f"than {RESET_AFTER:g} s (reset_after) plus two frame intervals back, so "
                    "after the first lap it drops them as duplicates; loop a longer bag")
            result.laps += 1
    except ExternalShutdownException:  # SIGTERM or Ctrl-C: rclpy shut the context down
        raise KeyboardInterrupt from None
    except rclpy_implementation.RCLError:
        # Ctrl-C while publishing: rclpy's handler shut the context down under the publisher
        # ("publisher's context is invalid").
        if node.context.ok():
            raise
        raise KeyboardInterrupt from None
    finally:
        node.destroy_node()
        source.close()
        if own:
            shut_down()  # a Ctrl-C's handler may be shutting it down at the same moment
    return result
