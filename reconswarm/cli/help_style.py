"""How `--help` shows options and arguments: a switch takes no value, an argument is named in capitals.

typer's rich help (0.2x) shows every option's Python type in angle brackets, a switch too (`--secure
<bool>`, `--help <bool>`), and an argument as `{db}` in the usage line and `<list[Path]>` in its table.
`install()` adjusts typer's two parameter classes once, for every command of the application:
- a switch (a flag, not a counter) shows no value type; a repeatable option the type of one value
  (`--connect <str>`, not `<list[str]>`);
- an argument is shown by its metavar, or its name in capitals (`DB`, `SCENARIO...`), `[NAME]` when
  optional, in the usage line and the table, and its type by its element (`<path>...`, not
  `<list[Path]>`).
Without those classes (another typer), nothing is changed.
"""

from __future__ import annotations

from typing import Any

_installed = False


def _argument_name(param: Any) -> str:
    return str(param.metavar if param.metavar is not None else (param.name or "arg").upper())


def install() -> None:
    global _installed
    if _installed:
        return
    _installed = True
    try:
        from typer.core import TyperArgument, TyperOption
    except ImportError:  # pragma: no cover - another typer: its own help
        return
    if hasattr(TyperOption, "display_type_rich"):
        option_type = TyperOption.display_type_rich

        def _option_type(self: Any, ctx: Any) -> str | None:
            if getattr(self, "is_flag", False) and not getattr(self, "count", False):
                return None
            shown = option_type(self, ctx)
            if isinstance(shown, str) and shown.startswith("<list[") and shown.endswith("]>"):
                return f"<{shown[6:-2]}>"  # a repeatable option takes one value each time it is given
            return shown

        TyperOption.display_type_rich = _option_type  # type: ignore[method-assign]
    if hasattr(TyperArgument, "_usage_display_name"):
        def _usage(self: Any) -> str:
            name = _argument_name(self)
            if self.nargs != 1 and not name.endswith("..."):
                name += "..."
            return name if self.required else f"[{name}]"

        TyperArgument._usage_display_name = _usage  # type: ignore[method-assign]
    if hasattr(TyperArgument, "display_name_raw"):
        TyperArgument.display_name_raw = property(_argument_name)  # type: ignore[assignment, method-assign]
    if hasattr(TyperArgument, "display_type_rich"):
        argument_type = TyperArgument.display_type_rich

        def _argument_type(self: Any, ctx: Any) -> str | None:
            desc = getattr(self, "type_descriptor", None)
            if desc is not None and getattr(desc, "is_list", False):
                return "<path>..." if getattr(desc, "is_path", False) else None
            return argument_type(self, ctx)

        TyperArgument.display_type_rich = _argument_type  # type: ignore[method-assign]
