"""`cncctl tool`: the tool table, list, set and delete, kept by cncd (or in a tool.tbl file)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from controller.errors import CncError
from controller.operator.client import DaemonClient, DaemonError, DaemonUnavailable
from controller.operator.control_cmd import (
    EXIT_NO_DAEMON,
    EXIT_REFUSED,
    add_socket_argument,
    default_socket_path,
)
from controller.tools import Tool, ToolTable, check_tool, load_tool_table, save_tool_table

_FIELDS = {"P": "pocket", "Z": "length_mm", "D": "diameter_mm"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)
    parser.add_argument("action", choices=("list", "set", "delete"))
    parser.add_argument("words", nargs="*", help="set: T3 Z12.5 D6 [P3] (length and "
                        "diameter in mm; words not given keep their value); delete: T3")
    parser.add_argument("--comment", help="set: the tool's comment")
    parser.add_argument("--file", metavar="TBL", help="edit this tool.tbl (the file of an "
                        "embedded run's config, `tools.table_file`) instead of cncd's table")
    parser.add_argument("--json", action="store_true", help="the table as JSON")


def _request(args: argparse.Namespace) -> dict[str, Any]:
    """The `tool` request the words ask for; ValueError naming a bad word."""
    fields: dict[str, Any] = {"action": args.action}
    if args.action == "list":
        if args.words:
            raise ValueError("list takes no words")
        return fields
    for word in args.words:
        letter, number = word[:1].upper(), word[1:]
        if letter == "T" or letter == "P":
            if not number.isdigit():
                raise ValueError(f"{word!r}: {letter} takes a whole number")
            fields["tool" if letter == "T" else "pocket"] = int(number)
        elif letter in _FIELDS and args.action == "set":
            try:
                fields[_FIELDS[letter]] = float(number)
            except ValueError:
                raise ValueError(f"{word!r}: {letter} takes a number (mm)") from None
        else:
            raise ValueError(f"{word!r}: {args.action} takes "
                             f"{'T P Z D words' if args.action == 'set' else 'T'}")
    if "tool" not in fields:
        raise ValueError(f"{args.action} needs the tool number: T3")
    if args.comment is not None:
        fields["comment"] = args.comment
    return fields


def _in_file(path: str, fields: dict[str, Any]) -> list[dict[str, Any]]:
    """The request applied to a tool.tbl file (created by the first set)."""
    table: ToolTable = load_tool_table(path, missing_ok=fields["action"] == "set")
    if fields["action"] == "delete":
        try:
            table = table.without(fields["tool"])
        except KeyError:
            raise ValueError(f"T{fields['tool']} is not in {path}") from None
    elif fields["action"] == "set":
        old = table.get(fields["tool"]) or Tool(fields["tool"], fields["tool"])
        tool = Tool(old.number, fields.get("pocket", old.pocket),
                    fields.get("length_mm", old.length_mm),
                    fields.get("diameter_mm", old.diameter_mm), fields.get("comment", old.comment))
        check_tool(tool)
        table = table.with_tool(tool)
    if fields["action"] != "list":
        save_tool_table(path, table)
    return table.describe()


def tools_text(tools: list[dict[str, Any]]) -> str:
    """The table as an operator reads it: one row per tool."""
    if not tools:
        return "no tools in the table"
    rows = [f"{'tool':>6} {'pocket':>6} {'length mm':>10} {'diam mm':>8}  comment"]
    rows += [f"{'T' + str(t['tool']):>6} {t['pocket']:>6} {t['length_mm']:>10.4f} "
             f"{t['diameter_mm']:>8.4f}  {t['comment']}".rstrip() for t in tools]
    return "\n".join(rows)


def run(args: argparse.Namespace) -> int:
    try:
        fields = _request(args)
        if args.file is not None:
            tools = _in_file(args.file, fields)
        else:
            path = args.socket if args.socket is not None else default_socket_path()
            with DaemonClient(path) as client:
                tools = client.request("tool", **fields)["tools"]
    except (ValueError, CncError) as exc:
        print(f"cncctl tool: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except DaemonUnavailable as exc:
        print(f"cncctl: {exc} (is cncd running? or give --file tool.tbl)", file=sys.stderr)
        return EXIT_NO_DAEMON
    except DaemonError as exc:
        print(f"cncctl tool: {exc.code}: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    print(json.dumps(tools, indent=2) if args.json else tools_text(tools))
    return 0
