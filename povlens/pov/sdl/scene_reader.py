"""Reading a POV-Ray scene the way POV-Ray's parser walks it, to find its camera.

:class:`SceneReader` follows the statements of a scene, its ``#include`` files and its
macro calls through a :class:`~povlens.pov.sdl.directives.DirectiveStream` (which
processes the directives); objects and other blocks are skipped.  Its result is the
camera POV-Ray would use: the *last* camera statement met.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

from povlens.pov.sdl.camera_block import CameraState, parse_camera_block
from povlens.pov.sdl.directives import DirectiveStream, Frame, MacroCallError
from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.lexer import Token
from povlens.pov.sdl.values import UnknownValue, as_float

__all__ = ["SceneReader", "still_constants", "RADIOSITY_PRETRACE_DEFAULTS"]

#: POV-Ray 3.7.0.10's radiosity pretrace where a scene does not set it (fractions of the
#: image's larger side; its ``radiosity`` settings' constructor).
RADIOSITY_PRETRACE_DEFAULTS = {"pretrace_start": 0.08, "pretrace_end": 0.04}


def still_constants(clock: float | None, image_width: int | None,
                    image_height: int | None) -> dict[str, object]:
    """POV-Ray's built-in frame values for one image (measured with POV-Ray 3.7.0.10).

    Without a clock, as for a still: everything 0.  With ``+K V`` (one frame at clock V):
    ``clock`` = V and ``clock_on`` = 1, the rest 0.  ``image_width`` / ``image_height``
    are None when not given (an error if the scene uses them).
    """
    return {
        "clock": 0.0 if clock is None else float(clock),
        "clock_on": 0.0 if clock is None else 1.0,
        "clock_delta": 0.0,
        "frame_number": 0.0,
        "initial_clock": 0.0,
        "final_clock": 0.0,
        "initial_frame": 0.0,
        "final_frame": 0.0,
        "image_width": None if image_width is None else float(image_width),
        "image_height": None if image_height is None else float(image_height),
    }


class SceneReader:
    """Walks the scene file ``path`` (:meth:`run`) and keeps what POV-Ray would know at
    its end: ``camera`` (a :class:`CameraState`, an :class:`UnknownValue` saying why it
    cannot be told, or None), and the stream's ``included`` / ``unread_includes``.

    Parameters
    ----------
    path : the scene file.
    constants : :func:`still_constants`.
    library_paths : searched for ``#include`` files after the scene's folder.
    declares : names declared before the scene (POV-Ray's ``declare=NAME=VALUE``).
    """

    def __init__(self, path: Path, constants: dict[str, object],
                 library_paths: Sequence[Path] = (), declares: Mapping[str, object] | None = None):
        predefined = {k: v if isinstance(v, str) else float(v) for k, v in (declares or {}).items()}
        self.stream = DirectiveStream(path, library_paths, constants, predefined)
        self.stream.on_abandon = self._loop_abandoned
        self.camera: object = None
        self.camera_frames: list[Frame] = []  # the loops the camera statement was read in
        self.previous_cam = CameraState()  # for language versions < 3.5
        self.camera_count = 0
        #: The items of the scene's ``global_settings`` blocks (``radiosity``,
        #: ``photons``, ``assumed_gamma`` ...), as far as they can be read.
        self.global_settings: set[str] = set()
        #: The items of the scene's last ``photons`` block in ``global_settings`` as SDL
        #: text (names replaced by their values), "" if povlens cannot repeat it whole
        #: (a macro it cannot follow, a name without a value, the scene's own
        #: ``save_file``/``load_file``), None if there is none.
        self.photon_settings: str | None = None
        #: The radiosity pretrace the scene's ``global_settings`` leave POV-Ray with,
        #: (pretrace_start, pretrace_end) as fractions of the image's larger side
        #: (POV-Ray 3.7's defaults 0.08 and 0.04 where the blocks do not set them;
        #: later blocks change only what they set); None without radiosity, or when
        #: povlens cannot tell a value (a macro it cannot follow, a name without a
        #: value, a block inside a branch it cannot decide).
        self.radiosity_pretrace: tuple[float, float] | None = None
        self._pretrace: dict[str, float] = dict(RADIOSITY_PRETRACE_DEFAULTS)
        self._pretrace_known = True
        self._radiosity_seen = False

    @property
    def unread_includes(self) -> list[str]:
        return self.stream.unread_includes

    @property
    def written_files(self) -> list[str]:
        """``"file:line"`` of each ``#fopen`` that writes or appends, as read."""
        return self.stream.written_files

    @property
    def included(self) -> list[Path]:
        return self.stream.included

    def run(self) -> None:
        """Read the whole scene, directives and statements, to its end."""
        ds = self.stream
        ds.start()
        while True:
            try:
                tok = ds.next()
                if tok.kind == "eof":
                    break
                if tok.kind != "ident":
                    continue
                nxt = ds.peek(0, expand=False)
                if nxt.kind != "op" or nxt.text != "{":
                    continue
                if tok.text == "camera":
                    self._camera_statement(tok)
                elif tok.text == "global_settings":
                    ds.next()
                    self._global_settings_block()
                else:
                    ds.next()
                    ds.skip_rest()  # an object or other block
            except MacroCallError as exc:
                if exc.macro.has_camera:
                    self.camera = UnknownValue(
                        f"{exc}; the macro {exc.macro.name} (defined at {exc.macro.where}) makes "
                        f"a camera", hint=exc.hint)
            except SdlEvalError:
                continue  # a statement povlens cannot follow: the next one
        if self._radiosity_seen and self._pretrace_known:
            self.radiosity_pretrace = (self._pretrace["pretrace_start"],
                                       self._pretrace["pretrace_end"])

    def _camera_statement(self, tok: Token) -> None:
        ds = self.stream
        certain = ds.certain
        reason, hint = ds.uncertain_reason(), ds.uncertain_hint()
        tainted = ds.tainted
        cam = parse_camera_block(ds, ds.expr, tok, declared=False, symbol=ds.value_of,
                                 version=ds.version, previous=self.previous_cam)
        self.camera_count += 1
        self.camera_frames = [f for f in ds.frames if f.kind in ("while", "for")]
        if not certain:
            self.camera = UnknownValue(f"{tok.where}: the camera statement is inside {reason}",
                                       hint=hint)
            return
        if ds.tainted != tainted and not isinstance(cam, UnknownValue):
            self.camera = UnknownValue(f"{tok.where}: the camera's items depend on {ds.last_reason}",
                                       hint=ds.last_hint)
            return
        self.camera = cam
        if isinstance(cam, CameraState):
            self.previous_cam = cam

    def _global_settings_block(self) -> None:
        """After its '{': the block's items (names at its top level) into
        :attr:`global_settings`, to after its '}'."""
        ds = self.stream
        depth = 1
        while depth:
            try:
                tok = ds.next()
            except SdlEvalError:
                continue            # a macro povlens cannot follow: its items are unknown
            if tok.kind in ("eof", "stop"):
                return
            if tok.kind == "op" and tok.text in "{}":
                depth += 1 if tok.text == "{" else -1
            elif depth == 1 and tok.kind == "ident":
                self.global_settings.add(tok.text)
                nxt = ds.peek(0, expand=False)
                if tok.text == "photons" and nxt.kind == "op" and nxt.text == "{":
                    ds.next()
                    self.photon_settings = self._photons_items()
                elif tok.text == "radiosity" and nxt.kind == "op" and nxt.text == "{":
                    ds.next()
                    self._radiosity_items()

    def _radiosity_items(self) -> None:
        """After a ``radiosity`` block's '{': its ``pretrace_start`` and
        ``pretrace_end`` evaluated (:attr:`radiosity_pretrace`), to after its '}'."""
        ds = self.stream
        self._radiosity_seen = True
        if not ds.certain:
            self._pretrace_known = False    # POV-Ray may or may not read this block
        depth = 1
        while depth:
            try:
                tok = ds.next()
            except SdlEvalError:
                self._pretrace_known = False
                continue
            if tok.kind in ("eof", "stop"):
                return
            if tok.kind == "op" and tok.text in "{}":
                depth += 1 if tok.text == "{" else -1
            elif depth == 1 and tok.kind == "ident" and tok.text in self._pretrace:
                tainted = ds.tainted
                try:
                    value = ds.expr.parse()
                    value = None if isinstance(value, UnknownValue) else as_float(value, tok.text)
                except (SdlEvalError, TypeError, ValueError):
                    value = None
                if value is None or ds.tainted != tainted or not ds.certain:
                    self._pretrace_known = False
                else:
                    self._pretrace[tok.text] = value

    def _photons_items(self) -> str:
        """After a ``photons`` block's '{': its items as SDL text, to after its '}'
        (:attr:`photon_settings`; "" when they cannot be repeated whole)."""
        ds = self.stream
        depth, out, whole = 1, [], True
        while depth:
            try:
                tok = ds.next()
            except SdlEvalError:
                whole = False
                continue
            if tok.kind in ("eof", "stop"):
                return ""
            if tok.kind == "op" and tok.text in "{}":
                depth += 1 if tok.text == "{" else -1
                if not depth:
                    break
            text = _sdl_text(tok)
            whole = whole and text is not None and tok.text not in ("save_file", "load_file")
            out.append(text or "")
        return " ".join(out) if whole else ""

    def _loop_abandoned(self, frame: Frame, reason: str) -> None:
        if any(f is frame for f in self.camera_frames) and isinstance(self.camera, CameraState):
            self.camera = UnknownValue(f"{self.camera.where}: the camera statement is inside {reason}")


def _sdl_text(tok: Token) -> str | None:
    """A token as SDL text a later block can repeat: a declared name as its value (a
    number, a vector or a string), others as written; None for a name whose value
    povlens does not know."""
    if tok.kind != "ident" or tok.bound is None or tok.bound[0] is None:
        return tok.text
    value = tok.bound[0]
    if isinstance(value, bool) or isinstance(value, (int, float)):
        return repr(float(value))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    try:
        numbers = [float(v) for v in value]
    except (TypeError, ValueError):
        return None
    return "<" + ", ".join(repr(v) for v in numbers) + ">"
