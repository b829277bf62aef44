"""The parameter store: numbered (#1-#5601), named local (#<name>) and global (#<_name>)."""

from __future__ import annotations

from collections.abc import Callable

from controller.interpreter.system_params import SystemParams, is_system_number

MAX_PARAMETER = 5601  # LinuxCNC's numbered parameters (its rs274 refuses #5602)
LOCAL_NUMBERED = 30  # #1-#30 are a subroutine's arguments, saved and restored around a call
G28_HOME = 5161  # #5161-#5166: the G28 position (X Y Z A B C, machine coordinates, program units)
G30_HOME = 5181  # #5181-#5186: the G30 position


class ParamError(Exception):
    """A parameter that cannot be read or written; the caller adds file, line and word."""


class Parameters:
    """Numbered and named parameters with subroutine scopes.

    Reading a numbered parameter that was never set gives 0, as LinuxCNC reads it; the number
    is noted in `unset_reads` so that the interpreter warns (a typo in a parameter number then
    moves to 0, which the warning names). A subroutine call starts a scope:
    #1-#30 are its arguments (the ones not passed read 0) and named parameters without a
    leading underscore are its own; both are restored when it returns. `#<_name>` is global.
    Other parts of the interpreter (G28/G30, probing, tool length) read and write the
    numbered store through `get`/`set`."""

    def __init__(self) -> None:
        self.numbered: dict[int, float] = {}
        self.globals: dict[str, float] = {}
        self.locals: dict[str, float] = {}
        self._saved: list[tuple[dict[int, float] | None, dict[str, float]]] = []
        self.unset_reads: list[int] = []  # numbered parameters read as 0; the reader drains it
        self.system: SystemParams | None = None  # the read-only ones (set by the interpreter)
        self.on_return: Callable[[int], None] | None = None  # told the depth a return closes

    @property
    def depth(self) -> int:
        """How many subroutine calls are open."""
        return len(self._saved)

    def get(self, number: int) -> float:
        if self.system is not None and is_system_number(number):
            return self.system.numbered(number)  # type: ignore[return-value]
        _check_number(number)
        value = self.numbered.get(number)
        if value is None:
            self.unset_reads.append(number)
            return 0.0
        return value

    def is_set(self, number: int) -> bool:
        """Whether the numbered parameter was set (read it with `get`: 0 when it was not)."""
        return number in self.numbered

    def set(self, number: int, value: float) -> None:
        if is_system_number(number):
            raise ParamError(f"parameter #{number} is read-only (a system parameter)")
        _check_number(number)
        self.numbered[number] = value

    def get_named(self, name: str) -> float:
        store = self.globals if name.startswith("_") else self.locals
        value = store.get(name)
        if value is None and self.system is not None:
            value = self.system.named(name)
        if value is None:
            raise ParamError(f"named parameter #<{name}> is not set")
        return value

    def set_named(self, name: str, value: float) -> None:
        if self.system is not None and name in self.system.named_values:
            raise ParamError(f"parameter #<{name}> is read-only (a system parameter)")
        (self.globals if name.startswith("_") else self.locals)[name] = value

    def exists(self, name: str) -> bool:
        if self.system is not None and name in self.system.named_values:
            return True
        return name in (self.globals if name.startswith("_") else self.locals)

    def call(self, args: list[float] | None) -> None:
        """Open a subroutine scope with its arguments as #1, #2, ...; None (an M98 call):
        #1-#30 stay shared with the caller, only the named locals are the callee's own."""
        if args is None:
            self._saved.append((None, self.locals))
            self.locals = {}
            return
        if len(args) > LOCAL_NUMBERED:
            raise ParamError(f"a call passes at most {LOCAL_NUMBERED} arguments")
        saved = {n: v for n, v in self.numbered.items() if n <= LOCAL_NUMBERED}
        self._saved.append((saved, self.locals))
        for n in range(1, LOCAL_NUMBERED + 1):
            self.numbered[n] = args[n - 1] if n <= len(args) else 0.0
        self.locals = {}

    def ret(self) -> None:
        """Close the innermost subroutine scope: its caller's #1-#30 and locals come back."""
        if self.on_return is not None:
            self.on_return(len(self._saved))
        saved, self.locals = self._saved.pop()
        if saved is None:  # an M98 call: #1-#30 were the caller's all along
            return
        for n in range(1, LOCAL_NUMBERED + 1):
            self.numbered.pop(n, None)
        self.numbered.update(saved)


def _check_number(number: int) -> None:
    if not 1 <= number <= MAX_PARAMETER:
        raise ParamError(f"parameter #{number} out of range 1..{MAX_PARAMETER}")
