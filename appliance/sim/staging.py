"""The simulated bench's hands: what a person puts on a real box's base, placed for them.

The daemon asks for things through the front panel's Operator (hw/base.py): the empty
base, the printed chessboard held tilted or lying flat, the reference ball. On a real box
that is a message; here SimOperator records the request on the bench, and the camera
(StagedCamera) renders what was asked for instead of the part:

    empty        the base plate (its top at level zero: it shows once the ink is below it)
    board_views  the daemon's board held above the tank, the n-th of a set of tilted poses
    board_flat   the board lying on the base at the jig position the request states; seen
                 only once the base top stands at or above the ink
    reference    a ball of the requested diameter, put down a little off the base's centre
    clear        the part the bench was set up with

The level the camera sees is the bench's own truth (the factory's level at home, which
need not equal the daemon's setting: that is what level zero measures).
"""

from __future__ import annotations

import numpy as np

from ..hw.base import Camera, Operator, Placement

BALL_AT = (48.0, 52.5)  # where the simulated hand puts the reference ball (mm)


class SimOperator(Operator):
    def __init__(self, bench):
        self.bench = bench
        self.requests: list[Placement] = []

    def place(self, request: Placement) -> None:
        self.requests.append(request)
        self.bench.placement = None if request.kind == "clear" else request


def _board_poses(board, rig):
    """The tilted views of the sim's calibration set that keep this board whole in the frame."""
    from .boards import DEFAULT_POSES, true_corners

    keep = []
    for pose in DEFAULT_POSES:
        c = true_corners(board, pose, rig)
        if c.min() > 10 and c[:, 0].max() < rig.width - 10 and c[:, 1].max() < rig.height - 10:
            keep.append(pose)
    return keep


class StagedCamera(Camera):
    """The bench's camera: the part (`part_camera`) unless the operator was asked to place
    something else; `make_camera(surface)` gives a camera of the same kind for another part."""

    def __init__(self, bench, part_camera, make_camera, level_mm, rig, effects):
        self.bench, self.part_camera, self.make_camera = bench, part_camera, make_camera
        self.level_mm, self.rig, self.effects = level_mm, rig, effects
        self._cameras = {}
        self.captures = 0

    def _staged(self, surface):
        if surface.name not in self._cameras:
            self._cameras[surface.name] = self.make_camera(surface)
        return self._cameras[surface.name]

    def capture(self) -> np.ndarray:
        from . import surfaces

        self.captures += 1
        p = getattr(self.bench, "placement", None)
        if p is None:
            return self.part_camera.capture()
        if p.kind == "empty":
            return self._staged(surfaces.BASE_PLATE).capture()
        if p.kind == "reference":
            return self._staged(surfaces.ball(p.details.get("diameter_mm", 25.4), *BALL_AT)).capture()
        if p.kind in ("board_views", "board_flat"):
            return self._board(p)
        return self.part_camera.capture()

    def _board(self, p: Placement) -> np.ndarray:
        from .boards import Board, Pose, render_board
        from .effects import Effects

        d = p.details
        cols, rows = d["inner_corners"]
        board = Board(cols, rows, float(d["square_mm"]))
        effects = Effects(blur_sigma_px=0.6, noise_sigma=1.5, lens_distortion=self.effects.lens_distortion)
        rng = np.random.default_rng([7, p.view, self.captures])
        if p.kind == "board_views":
            poses = _board_poses(board, self.rig)
            return render_board(board, poses[p.view % len(poses)], self.rig, effects, rng)
        level = float(self.level_mm())
        if level > 0.05:  # the base, and the board on it, are under the ink
            from .surfaces import BASE_PLATE

            return self._staged(BASE_PLATE).capture()
        # the jig's first corner (nearest the image's top-left) and the rows' direction -> the centre
        a = np.radians(float(d.get("angle_deg", 0.0)))
        along, down = np.array([np.cos(a), np.sin(a)]), np.array([np.sin(a), -np.cos(a)])
        x0, y0 = d["first_corner_mm"]
        c = (
            np.array([x0, y0])
            + along * (cols - 1) * board.square_mm / 2
            + down * (rows - 1) * board.square_mm / 2
        )
        # (the corners are symmetric about the centre: the detector orders them the same either way up)
        pose = Pose(0.0, 0.0, float(np.degrees(a)), float(c[0]), float(c[1]), -level)
        return render_board(board, pose, self.rig, effects, rng)

    def note_move_finished(self):
        """The virtual camera's ripple clock (sim/camera.py) restarts when the stage stops."""
        hint = getattr(self.part_camera, "note_move_finished", None)
        if hint is not None:
            hint()

    def close(self) -> None:
        for cam in [self.part_camera, *self._cameras.values()]:
            close = getattr(cam, "close", None)
            if close is not None:
                close()
