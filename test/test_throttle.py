"""Log throttling: one line per cause and period, a count of what was held back, and other
causes of the same drop reason reported at once."""
from fcop_ros.ros.throttle import LogThrottle


class Logger:
    def __init__(self):
        self.lines = []

    def warning(self, text):
        self.lines.append(text)

    info = warning


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_flood_of_one_problem_is_one_line_per_period_with_its_count():
    log, clock = Logger(), Clock()
    th = LogThrottle(log, 5.0, clock)
    for k in range(100):
        clock.t = k * 0.01
        th.warn("bad_encoding", f"depth: data has {1000 + k} bytes, step*height needs 2048")
    assert len(log.lines) == 1
    clock.t = 6.0
    th.warn("bad_encoding", "depth: data has 7 bytes, step*height needs 2048")
    assert len(log.lines) == 2 and log.lines[1].endswith("(100 such since the last report)")


def test_other_causes_of_the_same_reason_are_reported_at_once():
    """A reviewer saw six different bad-encoding causes after the first one stay silent."""
    log = Logger()
    th = LogThrottle(log, 5.0, Clock())
    causes = ["depth: unsupported encoding 'rgb8'", "nocs: unsupported encoding 'mono8'",
              "mask: unsupported encoding '32FC1'", "depth: empty image (0x0, encoding 32FC1)"]
    for text in causes * 3:
        th.warn("bad_encoding", text)
    assert log.lines == causes
