"""The machinery of `langpref`'s command line: options derived from the config dataclasses, a registry of
commands, and the resolved config written beside every output.

`add_config(parser, Cls)` adds one option per field of a config dataclass: `--field-name` (a `bool` that defaults
to True becomes `--no-field-name`), typed by its annotation, defaulting to its default, with the docstring under the
field as its help. A nested config's fields join in with `DEST.` in front of their destination (not of their flag),
and `from_args(Cls, args)` builds the config back from the parsed arguments. `opts` renames a flag (a string), leaves
a field out (None), or overrides argparse keywords (a dict, where "aliases" adds more flags) for the few flags whose
names predate this module.

`@command(name, help, options)` registers a command; `make_parser` builds only the options of the command being
run, so `--help` imports nothing heavy. `record(args, where, config)` writes the resolved config of a command with
its command line and langpref's version; a command that records takes `RERUN` (`--config PATH`), which reruns the
recorded command line with the options given after it overriding the record's (`expand_rerun`).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib
import inspect
import itertools
import json
import re
import shlex
import sys
import textwrap
import types
import typing
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

Options = Callable[[argparse.ArgumentParser], None]
COMMANDS: dict[str, tuple[str, str | None, list[Options], Callable[[argparse.Namespace], None]]] = {}


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of dataclass `cls`, whitespace collapsed."""
    try:
        body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
    except (OSError, TypeError):
        return {}
    return {
        a.target.id: " ".join(b.value.value.split())
        for a, b in itertools.pairwise(body)
        if isinstance(a, ast.AnnAssign)
        and isinstance(a.target, ast.Name)
        and isinstance(b, ast.Expr)
        and isinstance(b.value, ast.Constant)
        and isinstance(b.value.value, str)
    }


def _comma_tuple(item: type):
    def parse(text: str) -> tuple:
        return tuple(item(x) for x in text.split(","))

    parse.__name__ = f"comma-separated {item.__name__}s"
    return parse


def _base_type(hint: Any) -> Any:
    """`X | None` -> X; `tuple[T, ...]` -> a parser of "a,b,c" into a tuple of T; `Literal[a, b]` -> the type of a."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        return _base_type(args[0])
    if typing.get_origin(hint) is typing.Literal:
        return type(args[0])
    if typing.get_origin(hint) is tuple:
        return _comma_tuple(args[0])
    return hint


def literal_choices(hint: Any) -> tuple | None:
    """The values of a `Literal[...]` field (also of `Literal[...] | None`): its flag's `choices`; else None."""
    if typing.get_origin(hint) is typing.Literal:
        return typing.get_args(hint)
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        return next((c for a in typing.get_args(hint) if (c := literal_choices(a)) is not None), None)
    return None


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else dataclasses.MISSING


def add_config(
    p: argparse.ArgumentParser,
    cls: type,
    opts: dict[str, Any] | None = None,
    *,
    prefix: str = "",
    flag_prefix: str = "",
    only: tuple[str, ...] | None = None,
    unset: bool = False,
    common: tuple[str, ...] | None = None,
) -> None:
    """Add an option for each field of `cls` (see the module docstring); `only` keeps the named (dotted) fields;
    `unset`: options default to None ("not given") and say the field's default in their help; `common`: the (dotted)
    fields `--help` shows, the others only `--help-all` (None: all of them)."""
    opts, hints, docs = opts or {}, typing.get_type_hints(cls), field_docs(cls)
    for f in dataclasses.fields(cls):
        name, hint, default = prefix + f.name, hints[f.name], _default(f)
        spec = opts.get(name, {})
        if spec is not None and dataclasses.is_dataclass(hint):
            add_config(p, hint, opts, prefix=name + ".", flag_prefix=flag_prefix, only=only, unset=unset, common=common)
        if spec is None or dataclasses.is_dataclass(hint) or (only is not None and name not in only):
            continue
        spec = {"flag": spec} if isinstance(spec, str) else dict(spec)
        flag = spec.pop("flag", "--" + flag_prefix + f.name.replace("_", "-"))
        aliases = spec.pop("aliases", ())
        own_help = spec.pop("help", None)
        text = own_help or docs.get(f.name, "")
        kw: dict[str, Any] = {"dest": name}
        if literal_choices(hint) is not None and "choices" not in spec:
            spec["choices"] = literal_choices(hint)
        if hint is bool:
            flag = flag if default is False or flag.startswith("--no-") else "--no-" + flag[2:]
            kw["action"] = "store_true" if default is False else "store_false"
            if default is True and not own_help and text:  # the field's docstring says what the flag turns off
                text = f"Turn off, on by default: {text}"
        elif default is dataclasses.MISSING or default == "":
            kw.update(required=True, type=_base_type(hint))
        else:
            kw.update(type=_base_type(hint), default=None if unset else default)
            if default not in (None, ()) and "default" not in text.lower() and not spec.get("required"):
                shown = ",".join(map(str, default)) if isinstance(default, tuple) else default
                text += f" (default {shown})"
        if spec.pop("positional", False):
            flag, kw = f.name, {k: v for k, v in kw.items() if k in ("type", "default")}
        elif "type" in kw and "choices" not in spec:
            kw["metavar"] = flag.lstrip("-").replace("-", "_").upper()
        kw.update(spec)
        hidden = common is not None and name not in common and not kw.get("required")
        if hidden:
            _more_help(p)
        shown = not hidden or _HELP_ALL[0]
        if common is not None and not _HELP_ALL[0]:
            text = _first_sentence(text)  # --help is a summary; --help-all has every word
        p.add_argument(flag, *aliases, help=text.replace("%", "%%") if shown else argparse.SUPPRESS, **kw)


def _first_sentence(text: str) -> str:
    """The first sentence of an option's help, with its default when the help ends by stating one."""
    default = re.search(r" \(default [^()]*\)$", text)
    head = re.split(r"(?<![Ee]q\.)(?<!e\.g\.)(?<=\.)\s", text, maxsplit=1)[0]
    return head + (default.group(0) if default and default.group(0) not in head else "")


def args_of(args: argparse.Namespace, prefix: str = "") -> dict[str, Any]:
    """The parsed values whose destination starts with `prefix`, keyed by the rest of it."""
    return {k[len(prefix) :]: v for k, v in vars(args).items() if k.startswith(prefix)}


def from_args(cls: type, args: argparse.Namespace, prefix: str = "", **given: Any) -> Any:
    """An instance of `cls` from the options `add_config` added (fields without an option keep their default);
    `given` sets fields outright."""
    hints, values, kw = typing.get_type_hints(cls), args_of(args, prefix), {}
    for f in dataclasses.fields(cls):
        if f.name in given:
            kw[f.name] = given[f.name]
        elif dataclasses.is_dataclass(hints[f.name]):
            kw[f.name] = from_args(hints[f.name], args, prefix + f.name + ".")
        elif f.name in values:
            kw[f.name] = values[f.name]
    return cls(**kw)


# ---- commands: registry, options, output --------------------------------------------------------------------------


_HELP_ALL = [False]
"""Whether this parser is built for `--help-all` (every option shown), set by `make_parser`."""
HELP_ALL_NOTE = "Shown: the common options; `--help-all` lists every option."


def command(name: str, help: str, options: list[Options], description: str | None = None):
    """Register the decorated function as `langpref NAME`; each of `options` adds options to its parser."""

    def register(run: Callable[[argparse.Namespace], None]) -> Callable[[argparse.Namespace], None]:
        COMMANDS[name] = (help, description, options, run)
        return run

    return register


def _more_help(p: argparse.ArgumentParser) -> None:
    """Mark `p` as having options `--help` leaves out: the command gains `--help-all` (`make_parser`). An attribute
    of the parser, not a default, so that no command's recorded config holds it."""
    p._langpref_more_help = True  # type: ignore[attr-defined]


def rare(*adds: Options) -> Options:
    """The options `adds` add, listed by `--help-all` only: for options not built by `add_config` (whose `common`
    names the options `--help` shows). A required option stays in `--help`."""

    def add(p: argparse.ArgumentParser) -> None:
        first = len(p._actions)
        for each in adds:
            each(p)
        for action in p._actions[first:]:
            if not action.required:
                _more_help(p)
                if not _HELP_ALL[0]:
                    action.help = argparse.SUPPRESS

    return add


def opt(*flags: str, **kw: Any) -> Options:
    return lambda p: p.add_argument(*flags, **kw)


def path(*flags: str, **kw: Any) -> Options:
    return opt(*flags, type=Path, **kw)


def config(where: str, opts: dict | Callable[[], dict] | None = None, **kw: Any) -> Options:
    """The options of the config dataclass `module:Class` (imported only when the command's options are built)."""

    def add(p: argparse.ArgumentParser) -> None:
        module, name = where.split(":")
        add_config(p, getattr(importlib.import_module(module), name), opts() if callable(opts) else opts, **kw)

    return add


RERUN_HELP = (
    "rerun the command recorded in this resolved config (COMMAND.config.json, STEM.config.json), the options given "
    "here overriding the record's (a switch it turned on: its --no- form)"
)
RERUN = opt("--config", metavar="PATH", type=Path, help=RERUN_HELP)
"""The `--config PATH` option of every command that records its resolved config (`record`)."""


def command_of(args: argparse.Namespace, shown: bool = False) -> str:
    """The command line that ran (with `--config`, the recorded one followed by the options given with it);
    `shown`: without `--json`, which changes only how the result is printed (for a command written into results)."""
    return shlex.join(["langpref", *(a for a in args.argv if not (shown and a == "--json"))])


def _command_name(argv: list[str]) -> str | None:
    """The registered command `argv` starts with (its longest match), if any."""
    words = list(itertools.takewhile(lambda a: not a.startswith("-"), argv))
    return next((" ".join(words[:n]) for n in range(len(words), 0, -1) if " ".join(words[:n]) in COMMANDS), None)


def expand_rerun(argv: list[str], parser_for: Callable[[list[str]], argparse.ArgumentParser]) -> list[str]:
    """`argv` with `--config PATH` replaced by the command line recorded at PATH, for a command that takes
    `--config` (`RERUN`): the recorded arguments, less the options `argv` gives again, then the others of `argv`
    (`parser_for(argv)` builds the parser that says which tokens are an option's values). Any other `argv` is
    returned as it is (argparse then reports a misplaced `--config`)."""
    at = next((i for i, a in enumerate(argv) if a == "--config" or a.startswith("--config=")), None)
    name = _command_name(argv)
    if at is None or name is None or RERUN not in COMMANDS[name][2]:
        return argv
    if argv[at] == "--config":
        if at + 1 >= len(argv):
            return argv
        where, rest = argv[at + 1], argv[:at] + argv[at + 2 :]
    else:
        where, rest = argv[at].split("=", 1)[1], argv[:at] + argv[at + 1 :]
    try:
        saved = json.loads(Path(where).read_text())
        recorded = saved["command"]
    except FileNotFoundError:
        raise LangprefError(f"--config {where}: no such file; give the .config.json a command wrote") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise LangprefError(
            f"--config {where} is not a resolved config written by langpref ({type(exc).__name__}); give the "
            ".config.json a command wrote"
        ) from None
    words = shlex.split(recorded)[1:]
    if _command_name(words) != name:
        raise LangprefError(f"--config {where} records `{recorded[:60]}`, not `langpref {name}`; run that command")
    _warn_if_other_version(where, saved.get("langpref_version"))
    given = rest[len(name.split()) :]
    return [*_without_given(_leaf(parser_for(words), name), words, given), *given]


def _warn_if_other_version(where: str, version: Any) -> None:
    """One line on stderr when the record at `where` was written by another langpref: the command line replays, but
    a default that changed since then applies now, so the rerun may differ from the record."""
    from langpref import __version__

    if version != __version__:
        print(
            f"warning: --config {where} was recorded by langpref {version or 'of unknown version'}, this is "
            f"{__version__}: defaults that changed since then apply",
            file=sys.stderr,
        )


def _leaf(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    """The parser of command `name` inside the top-level `parser`."""
    for word in name.split():
        (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[word]
    return parser


def _without_given(p: argparse.ArgumentParser, recorded: list[str], given: list[str]) -> list[str]:
    """`recorded` without the options (and their values) whose destination `given` sets again, so that a rerun's
    record does not grow with each override. Options that accumulate (`append`) are kept: argparse adds to them."""
    actions = p._option_string_actions

    def action(token: str) -> argparse.Action | None:
        return actions.get(token.split("=", 1)[0]) if token.startswith("-") else None

    again = {a.dest for a in map(action, given) if a is not None}
    out, i = [], 0
    while i < len(recorded):
        a = action(recorded[i])
        replaced = a is not None and a.dest in again and a.nargs in (None, 0)
        if not replaced or isinstance(a, argparse._AppendAction):
            out.append(recorded[i])
            i += 1
        else:
            i += 1 if "=" in recorded[i] or a.nargs == 0 else 2
    return out


def _add_inverse_switches(p: argparse.ArgumentParser) -> None:
    """For each on/off switch, its opposite (`--x` and `--no-x`), hidden from `--help`, so that a rerun with
    `--config` can turn off a switch its record turned on."""
    taken = {o for a in p._actions for o in a.option_strings}
    for action in list(p._actions):
        if not isinstance(action, argparse._StoreTrueAction | argparse._StoreFalseAction) or not action.option_strings:
            continue
        flag = action.option_strings[0]
        other = "--" + flag[5:] if flag.startswith("--no-") else "--no-" + flag[2:]
        if other not in taken:
            value = not isinstance(action, argparse._StoreTrueAction)
            p.add_argument(other, dest=action.dest, action="store_const", const=value, help=argparse.SUPPRESS)
            taken.add(other)


def emit(obj: Any, as_json: bool, human: Callable[[Any], str] | None = None) -> None:
    print(json.dumps(obj) if as_json else human(obj) if human else json.dumps(obj, indent=2))


def record(args: argparse.Namespace, where: str | Path, config: Any = None, **inputs: Any) -> None:
    """Write the resolved `config` (default: the command's options), beside the `inputs` that are not part of it,
    with the command line and langpref's version, as JSON at `where`."""
    from langpref import __version__

    if config is None:
        config = {
            k: v
            for k, v in vars(args).items()
            if k not in ("func", "argv", "json", "command", "experiment", "study_command", "bank_command", "config")
        }
    out = {
        "langpref_version": __version__,
        "command": command_of(args),
        "config": {**inputs, "config": config} if inputs else config,
    }
    Path(where).parent.mkdir(parents=True, exist_ok=True)
    Path(where).write_text(
        json.dumps(out, indent=2, default=lambda o: dataclasses.asdict(o) if dataclasses.is_dataclass(o) else str(o))
        + "\n"
    )


def beside(file: str | Path) -> Path:
    return Path(file).with_suffix(".config.json")


def make_parser(
    prog: str, description: str, groups_help: dict[str, tuple[str, str, str]], argv: list[str] | None = None
) -> argparse.ArgumentParser:
    """Every registered command with its help (`groups_help`: help, dest and metavar of each group of commands); a
    command's options only when `argv` names it (all of them without `argv`), so the others import nothing. A
    command whose config names its common options (`config(..., common=...)`) shows only those with `--help`, every
    option with `--help-all`."""
    _HELP_ALL[0] = argv is None or "--help-all" in argv  # every parser at once (docs, tests): all of every help
    parser = argparse.ArgumentParser(prog=prog, description=description)
    top = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    groups: dict[str, Any] = {}
    for name, (text, about_cmd, options, run) in COMMANDS.items():
        *group, leaf = name.split()
        if group and group[0] not in groups:
            about, dest, metavar = groups_help[group[0]]
            g = top.add_parser(group[0], help=about, description=about[0].upper() + about[1:] + ".")
            groups[group[0]] = g.add_subparsers(dest=dest, required=True, metavar=metavar)
        p = (groups[group[0]] if group else top).add_parser(
            leaf, help=text, description=about_cmd or text[0].upper() + text[1:] + "."
        )
        p.set_defaults(func=run)
        if argv is None or argv[: len(group) + 1] == [*group, leaf]:
            for add in options:
                add(p)
            more = getattr(p, "_langpref_more_help", False)
            p.add_argument(
                "--help-all", action="help", help="show every option" + (", not only the common ones" if more else "")
            )
            if more and not _HELP_ALL[0]:
                p.description = f"{p.description} {HELP_ALL_NOTE}"
            if RERUN in options:
                _add_inverse_switches(p)
    return parser
