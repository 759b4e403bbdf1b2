"""Camera conventions every layer shares, so that each is written once."""


def image_centre(width: int, height: int) -> tuple[float, float]:
    """The principal point assumed when none is given: the image centre, with pixel centres at
    integer coordinates (REP-104 / OpenCV)."""
    return (width - 1) / 2.0, (height - 1) / 2.0
