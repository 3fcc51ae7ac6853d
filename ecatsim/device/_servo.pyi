"""Type stub of the compiled servo loop (ecatsim/device/_servo.c)."""

def run(
    n: int,
    kind: int,
    ref: float,
    v_ff: float,
    window: float,
    i_trip: float,
    index: bool,
    state: tuple[float, float, float, float, float, float],
    params: tuple[float, ...],
) -> tuple[int, int, float, float, float, float, float, float]: ...
