"""Help pages that show every word: the groups of the `persival` command line.

Click shortens each command's summary in a group's list to what fits one line ("Solve the FE
arm for one activation vector; write..."); this group wraps it instead. Plain (not rich) help
for the same reason: rich's option table cuts long option names at 80 columns.
"""

from __future__ import annotations

from typer.core import TyperGroup

__all__ = ["FullHelpGroup"]


class FullHelpGroup(TyperGroup):
    def format_commands(self, ctx, formatter) -> None:
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command.get_short_help_str(limit=10_000)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)
