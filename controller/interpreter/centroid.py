"""Centroid's M25 (Z to its home position) and M99 ending the main job, when the config says so.

Centroid's M-series manual: "M25 - Move Z to home position"; "M99 - Return from Macro or
Subprogram ... If M99 is encountered in the main job file, it will be interpreted as the end of
the job." FreeCAD's Centroid post ends every program with both. LinuxCNC refuses M25 and starts
the main program again at M99 (as Fanuc does), so each rule is the config's choice (`gcode.m25`,
`gcode.main_program_m99`) and warns once naming it.
"""

from __future__ import annotations

from controller.config import MachineConfig
from controller.interpreter.codes import WordError, g_name, m_refusal
from controller.interpreter.state import InterpState

M25_CODE = 25
_G53 = 530
_G0 = 0
_END = 2  # M2


class CentroidCodes:
    """M25 and the main program's M99 of one program, on the interpreter's state."""

    def __init__(self, state: InterpState) -> None:
        self.state = state
        gcode = state.config.gcode
        self.z_home = gcode.m25 == "z_home"
        self.ends_job = gcode.main_program_m99 == "end"
        self._m25_said = False

    def m25(self, gs: list[int], ms: list[int], vals: dict[str, float], lineno: int) -> None:
        """An M25 line: a rapid of Z alone to its home position (machine coordinates), as
        `G90 G53 G0 Z<home>`; the motion and distance modes in force stay."""
        if not self.z_home:
            raise WordError(
                "M25", f"{m_refusal(M25_CODE)}; gcode.m25: z_home reads it as Centroid does"
            )
        _alone(gs, ms, vals)
        home_mm = z_home_mm(self.state.config)
        if not self._m25_said:
            self._m25_said = True
            self.state.warn_word(
                lineno,
                "M25",
                f"Centroid's 'move Z to its home position': a "
                f"rapid of Z alone to machine Z{home_mm:g} "
                "(gcode.m25: z_home; LinuxCNC refuses M25)",
            )
        self._rapid_z(home_mm, lineno)

    def end_job(self, lineno: int) -> None:
        """M99 in the main program: the end of the job, as M2 ends it."""
        self.state.warn_word(
            lineno,
            "M99",
            "M99 in the main program ends the job, as M2 "
            "(gcode.main_program_m99: end, Centroid's rule; "
            "LinuxCNC's task and Fanuc start the program again)",
        )
        self.state.execute([], [_END], {}, lineno)

    def _rapid_z(self, home_mm: float, lineno: int) -> None:
        state = self.state
        modal = state.modal
        kept = (modal.motion, modal.absolute, modal.scale, state.moves.power_up_g0)
        # G53 is absolute (LinuxCNC refuses it in G91); Z in mm lands on home_mm exactly
        modal.absolute, modal.scale = True, 1.0
        try:
            state.execute([_G53, _G0], [], {"Z": home_mm}, lineno)
        finally:
            modal.motion, modal.absolute, modal.scale, state.moves.power_up_g0 = kept


def z_home_mm(config: MachineConfig) -> float:
    """Z's home position in machine mm: where its homing sequence leaves it (LinuxCNC's HOME),
    else the top of Z's travel. +Z is away from the work, and a mill's Z homes up: Centroid's
    M25 is the retract before a tool change, never a move toward the work."""
    if not config.has_axis("z"):
        raise WordError(
            "M25",
            f"M25 (gcode.m25: z_home) moves Z, and the machine has no Z "
            f"axis (config '{config.name}')",
        )
    homing = config.axis("z").homing
    return homing.final_mm if homing is not None else config.axis("z").travel_mm[1]


def _alone(gs: list[int], ms: list[int], vals: dict[str, float]) -> None:
    """M25 stands alone on its line (with N): what it would do with other words is unknown."""
    others = [g_name(g) for g in gs] + [f"M{m}" for m in ms if m != M25_CODE] + list(vals)
    if others:
        raise WordError(
            "M25",
            f"M25 (Centroid's Z home) stands alone on its line, with N only (not {others[0]})",
        )
