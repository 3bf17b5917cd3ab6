"""The parameter store: numbered (#1…#5602) and named (#<name>, #<_global>) parameters,
LinuxCNC's read-only predefined names, and expression evaluation against them (a mixin of
the interpreter)."""

from __future__ import annotations

from nurbscnc.program import coords
from nurbscnc.program.codes import G_53, G_59_1, G_80, G_93, G_94, G_95, G_98, G_99
from nurbscnc.program.control import N_LOCAL
from nurbscnc.program.expressions import MAX_PARAMETER, ExpressionError, evaluate
from nurbscnc.program.modal import G_OF_PLANE
from nurbscnc.program.parse import Block

#: #5400: the tool in the spindle; #5420–#5425: the current X, Y, Z in program units, A, B,
#: C in degrees (program coordinates).
TOOL_IN_SPINDLE = 5400
POSITION_FIRST, POSITION_LAST = 5420, 5425


class ParameterStore:
    """Numbered and named parameters (mixin of the interpreter: it provides ``params``,
    ``globals``, ``frames``, ``m``, ``coords``, ``prog``, ``line_no`` and ``error``)."""

    def read_numbered(self, index_f: float) -> float:
        index = self.param_index(index_f)
        if index <= N_LOCAL:
            return self.params.get(index, 0.0)
        if index == TOOL_IN_SPINDLE:  # (before the offsets' range claims it)
            return float(self.m.tool_loaded)
        if coords.is_coordinate_parameter(index):
            return self.coords.read(index)
        if POSITION_FIRST <= index <= POSITION_LAST:
            k = index - POSITION_FIRST
            return self.prog[k] / self.m.scale if k < 3 else self.program_abc_deg()[k - 3]
        return self.params.get(index, 0.0)

    def write_numbered(self, index: int, value: float) -> None:
        if coords.is_coordinate_parameter(index):
            self.coords.write(index, value)
        else:
            self.params[index] = value

    def param_index(self, index_f: float) -> int:
        """The parameter number ``#index_f`` names (rounded), checked to be in range."""
        index = int(round(index_f))
        if not 1 <= index <= MAX_PARAMETER:
            raise ExpressionError(f"parameter number #{index_f:g} out of range 1..{MAX_PARAMETER}")
        return index

    def read_named(self, name: str) -> float:
        if name.startswith("_"):
            if name in self.globals:
                return self.globals[name]
            value = self.predefined(name)
            if value is not None:
                return value
        elif name in self.frames[-1].named:
            return self.frames[-1].named[name]
        raise ExpressionError(f"named parameter #<{name}> is not defined")

    def declare_named(self, name: str, column: int) -> None:
        """An assignment to ``#<name>`` being read, as LinuxCNC's
        read_named_parameter_setting: a read-only name is an error; a new name exists from
        here on with the value 0, so ``#<h>=[#<h>+5]`` gives 5."""
        if name.startswith("_"):
            if self.predefined(name) is not None:
                raise self.error(f"Cannot assign to read-only parameter #<{name}>", column)
            self.globals.setdefault(name, 0.0)
        else:
            self.frames[-1].named.setdefault(name, 0.0)

    def exists(self, name: str) -> bool:
        if name.startswith("_"):
            return name in self.globals or self.predefined(name) is not None
        return name in self.frames[-1].named

    def predefined(self, name: str) -> float | None:
        """LinuxCNC's read-only named parameters, as its interp_namedparams.cc computes them
        (``_retract_r_plane`` is 1 under G99, whatever its comment says; ``_task`` 1 as in
        milltask, which makes the motion, not the preview)."""
        m = self.m
        system = self.coords.system  # 1..9 for G54..G59.3
        a, b, c = self.program_abc_deg()
        values = {
            "_x": self.prog[0] / m.scale,
            "_y": self.prog[1] / m.scale,
            "_z": self.prog[2] / m.scale,
            "_metric": float(not m.inch),
            "_imperial": float(m.inch),
            "_absolute": float(m.absolute),
            "_incremental": float(not m.absolute),
            "_feed": m.feed,
            "_rpm": m.spindle_rpm,
            "_current_tool": float(m.tool_loaded),
            "_selected_tool": float(m.tool_selected),
            "_line": float(self.line_no),
            "_motion_mode": float(m.motion if m.motion is not None else G_80),
            "_plane": float(G_OF_PLANE[m.plane]),
            "_coord_system": float(G_53 + 10 * system if system < 7 else G_59_1 - 7 + system),
            "_ccomp": float(m.comp_mode),
            "_inverse_time": float(m.feed_mode == G_93),
            "_units_per_minute": float(m.feed_mode == G_94),
            "_units_per_rev": float(m.feed_mode == G_95),
            "_tool_offset": float(any(self.coords.tool_mm)),
            "_retract_r_plane": float(m.retract_mode == G_99),
            "_retract_old_z": float(m.retract_mode == G_98),
            "_ijk_absolute_mode": float(m.arc_absolute),
            "_lathe_diameter_mode": 0.0,
            "_lathe_radius_mode": 1.0,
            "_spindle_on": float(m.spindle != "off"),
            "_spindle_cw": float(m.spindle == "cw"),
            "_a": a,
            "_b": b,
            "_c": c,
            "_u": 0.0,
            "_v": 0.0,
            "_w": 0.0,
            "_call_level": float(len(self.frames) - 1),
            "_remap_level": 0.0,
            "_value": 0.0,
            "_value_returned": 0.0,
            "_task": 1.0,
            "_vmajor": 2.9,  # LinuxCNC's sscanf("%lf%lf") of its version "2.9.x"
            "_vminor": 0.0,
        }
        return values.get(name)

    def evaluate(self, value, column: int, lenient: bool = False) -> float:
        """The value of an expression; ``lenient``: an undefined named parameter reads 0
        (an endsub's value read while its definition is skipped: LinuxCNC reads it without
        the sub's locals, and does not stop)."""
        if type(value) is float:
            return value
        named = self.read_named
        if lenient:

            def named(name):
                return self.read_named(name) if self.exists(name) else 0.0

        try:
            return evaluate(value, self.read_numbered, named, self.exists)
        except ExpressionError as exc:
            raise self.error(exc.message, column) from None

    def assign(self, block: Block) -> None:
        """The block's parameter assignments. They take effect at the end of the line's
        reading (LinuxCNC): every right-hand side sees the old values."""
        pending = []
        for target, raw, column in block.assigns:
            if target[0] != "#":  # a named parameter exists (0) from its assignment's reading
                self.declare_named(target[1], column)
            value = self.evaluate(raw, 1)
            if target[0] == "#":
                index_f = self.evaluate(target[1], 1)
                try:
                    pending.append((self.param_index(index_f), value))
                except ExpressionError as exc:
                    raise self.error(exc.message) from None
            else:
                pending.append((target[1], value))
        for key, value in pending:
            if type(key) is int:
                self.write_numbered(key, value)
            elif key.startswith("_"):
                self.globals[key] = value
            else:
                self.frames[-1].named[key] = value
