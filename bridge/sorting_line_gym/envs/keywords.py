"""The keyword arguments of the env constructors, declared once.

Every env face takes the line options as keyword arguments: the fields of
:class:`~sorting_line_gym.line.options.LineOptions`, which name, type, default and explain them.
Beside them a face declares a few parameters of its own in its ``__init__`` (``num_envs``,
``render_mode``, ``backend``, ``seed``, ...), which end in ``**keywords``. A :class:`Keywords`
says which line options a face takes and where its defaults differ; as a class decorator it
writes the face's full signature onto ``__init__`` (what ``help()`` and ``inspect.signature``
show) and appends every keyword with its default and meaning to the class docstring. In the
constructor, :meth:`Keywords.line_options` turns the given keywords into a ``LineOptions``: an
unknown or misspelt keyword is a TypeError naming it and the allowed ones, never a silent default.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import typing
from collections.abc import Collection, Mapping
from typing import Any, TypeVar

from ..line.options import LineOptions

#: What the faces' own parameters mean (a line option's meaning is its field's).
OWN_MEANINGS = {
    "num_envs": "how many lines the vector env steps together",
    "namespace": "the node's namespace, or a list of several nodes' namespaces the lines are spread over",
    "render_mode": '"rgb_array" or "human" (the dashboard of the paper\'s Figure 2), or None',
    "backend": '"ros" (the line is a node reached over ROS 2) or "native" (the library\'s line in this process)',
    "seed": "line k starts from seed + k (as VecEnv.seed() and PPO(seed=...) do), or None",
    "evolution": 'the schedule the line evolves by: "upgrade", "drift" (the ready ones) or a schedule file',
}

_FIELDS = {f.name: f for f in dataclasses.fields(LineOptions)}
_TYPES = typing.get_type_hints(LineOptions)

Face = TypeVar("Face", bound=type)


class Keywords:
    """The line options one face takes: all fields but ``exclude``, with ``defaults`` of its own."""

    def __init__(self, exclude: Collection[str] = (), **defaults: Any):
        unknown = [name for name in (*exclude, *defaults) if name not in _FIELDS]
        if unknown:
            raise ValueError(f"{unknown} are no fields of LineOptions: allowed {', '.join(_FIELDS)}")
        self.options = tuple(name for name in _FIELDS if name not in exclude)
        self.defaults = {name: defaults.get(name, _FIELDS[name].default) for name in self.options}
        self.face = "the env"
        self.own: dict[str, inspect.Parameter] = {}

    def __call__(self, face: Face) -> Face:
        """Decorates the face's class: its ``__init__`` (own parameters, then ``**keywords``) gets
        the full signature, the class docstring the keyword list."""
        init = vars(face)["__init__"]  # its own constructor, not an inherited one
        parameters = list(inspect.signature(init, eval_str=True).parameters.values())
        if parameters[-1].kind is not inspect.Parameter.VAR_KEYWORD:
            raise TypeError(f"{face.__name__}.__init__ must end in **keywords to take the line options")
        self.face = face.__name__
        self.own = {p.name: p for p in parameters[1:-1]}
        if both := [name for name in self.own if name in self.options]:
            raise TypeError(f"{self.face}.__init__ declares line options {both}: exclude them from its Keywords")
        options = [
            inspect.Parameter(
                name, inspect.Parameter.KEYWORD_ONLY, default=self.defaults[name], annotation=_TYPES[name]
            )
            for name in self.options
        ]
        init.__signature__ = inspect.Signature([*parameters[:-1], *options])
        face.__doc__ = (face.__doc__ or "") + self.doc()
        return face

    @property
    def allowed(self) -> list[str]:
        return [*self.own, *self.options]

    def doc(self) -> str:
        """The keyword list of the docstring: each keyword with its default and meaning."""
        lines = ["", "", "## Keyword arguments (with their defaults)"]
        for name in self.allowed:
            if name in self.own:
                default, meaning = self.own[name].default, OWN_MEANINGS[name]
            else:
                default, meaning = self.defaults[name], _FIELDS[name].metadata["meaning"]
            lines.append(f"- `{name}={default!r}`: {meaning}")
        return "\n".join(lines) + "\n"

    def check(self, given: Collection[str]) -> None:
        """A TypeError naming the first keyword of ``given`` the face does not take, and the allowed ones."""
        allowed = self.allowed
        for name in given:
            if name not in allowed:
                close = difflib.get_close_matches(name, allowed, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise TypeError(
                    f"{self.face}() got an unexpected keyword argument {name!r}{hint}: allowed {', '.join(allowed)}"
                )

    def line_options(self, keywords: Mapping[str, Any], **fixed: Any) -> LineOptions:
        """The line options of the constructor's ``keywords`` (the given ones; the others take the
        face's defaults) and ``fixed`` (what the face sets itself)."""
        self.check(keywords)
        return LineOptions(**{**self.defaults, **keywords, **fixed})

    def split(self, keywords: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
        """``keywords`` as (the face's own parameters, each given or its default; the line options
        given): what an entry point needs to make another backend's env from the same keywords."""
        self.check(keywords)
        own = {name: keywords.get(name, p.default) for name, p in self.own.items()}
        return own, {k: v for k, v in keywords.items() if k not in self.own}
