"""The process list of a ROS 2 launch XML file, read without the ``launch`` package (docs/deployment.md §9).

On the vehicle, ``ros2 launch`` (Jazzy's ``launch`` 3.4 / ``launch_ros`` 0.26) reads the launch files and starts
one process per ``<node>``. Neither package is on PyPI, so the development machines cannot run it; the pool-day
test (``test/test_pool_day.py``) and anyone checking a layout here start the same processes through
:class:`~hindrax_bringup.layout.process_runner.ProcessRunner` from the list this module reads out of the same installed
file. Why our own reader: the launch XML front end is only available inside ``launch``; the subset the project's
launch files use is small and is read here the way ``launch_xml``/``launch_ros`` read it (element and attribute
names, substitutions, conditions, the ``--ros-args`` a node gets); anything else is refused with
:class:`LaunchFileError`, never ignored.

Supported
    ``<launch>`` with ``<arg name default description/>``, ``<let name value/>``,
    ``<node pkg exec name namespace output respawn respawn_delay args launch-prefix exec_name if unless>`` holding
    ``<param from/>``, ``<param name value/>`` and ``<remap from to/>`` and ``<env name value/>``, ``<include file>``
    holding ``<arg name value/>``, ``<group>`` (with ``if``/``unless``), and ``<set_env name value/>`` (for the nodes
    after it in its ``<launch>`` or scoped ``<group>``, as ``launch`` does: included files see it, and one set in an
    included file stays set after the ``<include>``; a node's own ``<env>`` wins); the substitutions ``$(var NAME)``,
    ``$(find-pkg-share PKG)`` and ``$(env NAME [DEFAULT])``; conditions that evaluate to ``true``/``false``/``1``/``0``
    (any case), as ``launch.conditions.evaluate_condition_expression``.
Command of a node (``launch_ros.actions.Node``)
    ``<executable> [args...] --ros-args -r __node:=<name> [-r __ns:=<ns>] --params-file <file> ... -r from:=to``,
    the ``<param name value>`` elements written, as ``launch_ros`` does, to a parameter file keyed ``/**``, with
    each value typed by YAML (``true`` -> bool, ``2.0`` -> float, anything else a string).
Environment
    ``<set_env>`` and a node's ``<env>`` add to the environment the node's process inherits
    (:attr:`NodeProcess.env`); the vehicle launch file gives every vehicle process its DDS transport this way
    (:mod:`hindrax_common.process.dds_transport`).
Launch prefix
    ``launch-prefix="nice -n -5"`` puts that command, split as a shell would (``shlex``), before the executable
    (``launch_ros.actions.Node(prefix=...)``); the vehicle launch file gives the safety processes their scheduling
    priority this way (docs/deployment.md §1). Jazzy's launch then labels the process after the prefix's command
    (``[nice-3]``), so those nodes also set ``exec_name``, the label ``launch_ros`` prints instead; this reader keeps
    it (:attr:`NodeProcess.exec_name`) and labels processes by node name or executable.
Respawn
    ``respawn="true"`` restarts the process whenever it ends while the launch runs, after ``respawn_delay`` s
    (``launch.actions.ExecuteLocal``: on any exit, not only a failure)."""
from __future__ import annotations

import contextlib
import os
import re
import shlex
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import yaml
from ament_index_python.packages import get_package_share_directory

from . import composition

__all__ = ["LaunchFileError", "NodeProcess", "ament_share", "read_launch", "write_parameter_file"]

#: resolves ``$(find-pkg-share PKG)``: package name -> its share directory
ShareResolver = Callable[[str], Path]

_SUBSTITUTION = re.compile(r"\$\(([\w-]+)((?:\s+[^()\s]+)*)\s*\)")
_TRUE, _FALSE = ("true", "1"), ("false", "0")


class LaunchFileError(ValueError):
    """A launch file this reader cannot read as ``ros2 launch`` would: one line naming the file and the cause."""


@dataclass(frozen=True)
class NodeProcess:
    """One ``<node>`` of a launch file, with every substitution done.

    package / executable: what ``ros2 run`` would start. name: the node name (``-r __node:=``), or None.
    namespace: ``-r __ns:=`` or None. parameters: in the order given, each a parameter file (``Path``) or a
    mapping of parameter name -> typed value (one ``<param name value>`` run). remaps: (from, to) pairs.
    arguments: the ``args`` attribute, split on white space. launch_prefix: the ``launch-prefix`` command, split
    (module docstring). exec_name: the ``exec_name`` attribute (Jazzy's process label) or None.
    respawn / respawn_delay_s: see the module docstring (s). env: (name, value) pairs added to the inherited
    environment (``<set_env>``, then the node's ``<env>``). source: the launch file that declares the node."""

    package: str
    executable: str
    name: str | None
    namespace: str | None = None
    parameters: tuple = ()
    remaps: tuple[tuple[str, str], ...] = ()
    arguments: tuple[str, ...] = ()
    launch_prefix: tuple[str, ...] = ()
    exec_name: str | None = None
    respawn: bool = False
    respawn_delay_s: float = 0.0
    env: tuple[tuple[str, str], ...] = ()
    source: Path = field(default=Path(), compare=False)

    @property
    def label(self) -> str:
        """The name a runner and its logs use: the node name, else the executable."""
        return self.name or self.executable

    @property
    def node_names(self) -> tuple[str, ...]:
        """The ROS node names this process runs: a composed process's nodes
        (:func:`hindrax_bringup.layout.composition.node_names`), else :attr:`label`."""
        return composition.node_names(self.package, self.executable, self.name)

    def ros_arguments(self, write_values: Callable[[Mapping], Path]) -> list[str]:
        """Everything after the executable (module docstring, "Command of a node"). ``write_values`` writes one
        mapping of ``<param name value>`` values to a parameter file and returns its path."""
        out = list(self.arguments) + ["--ros-args"]
        if self.name:
            out += ["-r", f"__node:={self.name}"]
        if self.namespace:
            out += ["-r", f"__ns:={self.namespace}"]
        for p in self.parameters:
            out += ["--params-file", str(p if isinstance(p, Path) else write_values(p))]
        for src, dst in self.remaps:
            out += ["-r", f"{src}:={dst}"]
        return out


def ament_share(package: str) -> Path:
    """``$(find-pkg-share PACKAGE)`` through the ament index of this environment (``AMENT_PREFIX_PATH``, a colcon
    install or ``/opt/ros``); in a repository checkout whose packages are not in the index (the development venv),
    the package's source directory ``src/<package>``, which holds the same ``launch/`` and ``config/``. Raises
    :class:`LaunchFileError` when neither has the package."""
    with contextlib.suppress(Exception):  # not in the index (or no index at all): try the checkout
        return Path(get_package_share_directory(package))
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "src" / package
        if (candidate / "package.xml").is_file():
            return candidate
    raise LaunchFileError(f"$(find-pkg-share {package}): package not found in the ament index "
                          f"(AMENT_PREFIX_PATH={os.environ.get('AMENT_PREFIX_PATH', '')}) nor in a checkout")


def read_launch(path: str | os.PathLike, arguments: Mapping[str, str] | None = None,
                find_share: ShareResolver = ament_share) -> list[NodeProcess]:
    """The node processes ``ros2 launch`` would start for the launch file at ``path`` with ``arguments``
    (``name:=value`` of the command line, as a mapping), includes followed, conditions applied, in file order.

    Raises :class:`LaunchFileError` for an unreadable file, an unsupported element, attribute or substitution, an
    argument that is not declared or has no value, or a condition that is not a boolean."""
    return _Reader(find_share).read(Path(path), dict(arguments or {}), top=True)


def write_parameter_file(values: Mapping, directory: str | os.PathLike) -> Path:
    """One run of ``<param name value>`` values as a new parameter file in ``directory``, keyed ``/**`` as
    ``launch_ros`` writes it, for :meth:`NodeProcess.ros_arguments`. Returns the file's path."""
    fd, name = tempfile.mkstemp(prefix="launch_params_", suffix=".yaml", dir=directory)
    with os.fdopen(fd, "w") as f:
        yaml.safe_dump({"/**": {"ros__parameters": dict(values)}}, f, default_flow_style=False)
    return Path(name)


class _Reader:
    def __init__(self, find_share: ShareResolver) -> None:
        self.find_share = find_share

    def read(self, path: Path, given: dict[str, str], top: bool,
             env: dict[str, str] | None = None) -> list[NodeProcess]:
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as exc:
            raise LaunchFileError(f"{path}: cannot read: {exc}") from exc
        if root.tag != "launch":
            raise LaunchFileError(f"{path}: root element <{root.tag}>, expected <launch>")
        declared = [a.get("name") for a in root.iter("arg") if a.get("name") and _is_declaration(root, a)]
        unknown = sorted(set(given) - set(declared))
        if unknown:
            kind = "launch argument" if top else "include argument"
            raise LaunchFileError(f"{path.name}: {kind}(s) {', '.join(unknown)} not declared "
                                  f"(declared: {', '.join(declared) or 'none'})")
        scope: dict[str, str] = {}
        return self._children(root, path, scope, given, {} if env is None else env)  # an include shares it

    def _children(self, parent: ET.Element, path: Path, scope: dict[str, str], given: dict[str, str],
                  env: dict[str, str]) -> list:
        out: list[NodeProcess] = []
        for el in parent:
            if not isinstance(el.tag, str):  # comments
                continue
            if el.tag == "arg":
                name = _required(el, "name", path)
                if name in given:
                    scope[name] = given[name]
                elif el.get("default") is not None:
                    scope[name] = self.sub(el.get("default"), scope, path)
                else:
                    raise LaunchFileError(f"{path.name}: argument {name!r} has no default and was not given")
                continue
            if el.tag == "let":
                scope[_required(el, "name", path)] = self.sub(_required(el, "value", path), scope, path)
                continue
            if el.tag == "set_env":
                _only(el, {"name", "value"}, path)
                env[self.sub(_required(el, "name", path), scope, path)] = self.sub(_required(el, "value", path),
                                                                                    scope, path)
                continue
            if not self._enabled(el, scope, path):
                continue
            if el.tag == "node":
                out.append(self._node(el, path, scope, env))
            elif el.tag == "include":
                file = Path(self.sub(_required(el, "file", path), scope, path))
                passed = {}
                for a in el:
                    if not isinstance(a.tag, str):
                        continue
                    if a.tag != "arg":
                        raise LaunchFileError(f"{path.name}: <{a.tag}> inside <include> is not supported")
                    passed[_required(a, "name", path)] = self.sub(_required(a, "value", path), scope, path)
                out += self.read(file, passed, top=False, env=env)
            elif el.tag == "group":
                _only(el, {"if", "unless", "scoped"}, path)
                scoped = self.sub(el.get("scoped", "true"), scope, path).lower() in _TRUE
                out += self._children(el, path, dict(scope) if scoped else scope, {}, dict(env) if scoped else env)
            else:
                raise LaunchFileError(f"{path.name}: element <{el.tag}> is not supported by this reader")
        return out

    def _enabled(self, el: ET.Element, scope: dict[str, str], path: Path) -> bool:
        enabled = True
        for attr, want in (("if", True), ("unless", False)):
            if el.get(attr) is None:
                continue
            value = self.sub(el.get(attr), scope, path).strip().lower()
            if value not in _TRUE + _FALSE:
                raise LaunchFileError(f"{path.name}: condition {attr}={el.get(attr)!r} evaluates to {value!r}, "
                                      f"expected true, false, 1 or 0")
            enabled = enabled and ((value in _TRUE) == want)
        return enabled

    def _node(self, el: ET.Element, path: Path, scope: dict[str, str], env: Mapping[str, str]) -> NodeProcess:
        _only(el, {"pkg", "exec", "name", "namespace", "output", "respawn", "respawn_delay", "args", "launch-prefix",
                   "exec_name", "if", "unless"}, path)
        sub = lambda text: self.sub(text, scope, path)  # noqa: E731
        params: list = []
        remaps: list[tuple[str, str]] = []
        node_env = dict(env)
        for child in el:
            if not isinstance(child.tag, str):
                continue
            if child.tag == "param" and child.get("from") is not None:
                _only(child, {"from"}, path)
                params.append(Path(sub(child.get("from"))))
            elif child.tag == "param":
                _only(child, {"name", "value"}, path)
                name, value = sub(_required(child, "name", path)), sub(_required(child, "value", path))
                if not params or isinstance(params[-1], Path):
                    params.append({})
                params[-1][name] = _typed(value)
            elif child.tag == "remap":
                _only(child, {"from", "to"}, path)
                remaps.append((sub(_required(child, "from", path)), sub(_required(child, "to", path))))
            elif child.tag == "env":
                _only(child, {"name", "value"}, path)
                node_env[sub(_required(child, "name", path))] = sub(_required(child, "value", path))
            else:
                raise LaunchFileError(f"{path.name}: <{child.tag}> inside <node> is not supported by this reader")
        respawn = sub(el.get("respawn", "false")).strip().lower()
        if respawn not in _TRUE + _FALSE:
            raise LaunchFileError(f"{path.name}: respawn={el.get('respawn')!r}: expected true or false")
        delay_text = el.get("respawn_delay", "0.0")  # launch_ros reads it as a float literal, no substitution
        try:
            delay = float(delay_text)
        except ValueError:
            raise LaunchFileError(f"{path.name}: respawn_delay={delay_text!r}: expected a number of seconds") from None
        if delay < 0.0:
            raise LaunchFileError(f"{path.name}: respawn_delay={delay_text!r}: expected a non-negative number")
        return NodeProcess(
            package=sub(_required(el, "pkg", path)), executable=sub(_required(el, "exec", path)),
            name=sub(el.get("name")) if el.get("name") else None,
            namespace=sub(el.get("namespace")) if el.get("namespace") else None,
            parameters=tuple(p if isinstance(p, Path) else dict(p) for p in params), remaps=tuple(remaps),
            arguments=tuple(sub(el.get("args", "")).split()), launch_prefix=tuple(shlex.split(sub(el.get(
                "launch-prefix", "")))), exec_name=sub(el.get("exec_name")) if el.get("exec_name") else None,
            respawn=respawn in _TRUE, respawn_delay_s=delay, env=tuple(node_env.items()),
            source=path)

    def sub(self, text: str, scope: Mapping[str, str], path: Path) -> str:
        """``text`` with its substitutions done (module docstring)."""
        def one(m: re.Match) -> str:
            kind, words = m.group(1), m.group(2).split()
            if kind == "var" and len(words) == 1:
                if words[0] not in scope:
                    raise LaunchFileError(f"{path.name}: $(var {words[0]}): no such argument")
                return scope[words[0]]
            if kind == "find-pkg-share" and len(words) == 1:
                return str(self.find_share(words[0]))
            if kind == "env" and len(words) in (1, 2):
                value = os.environ.get(words[0], words[1] if len(words) == 2 else None)
                if value is None:
                    raise LaunchFileError(f"{path.name}: $(env {words[0]}): not set and no default")
                return value
            raise LaunchFileError(f"{path.name}: substitution {m.group(0)!r} is not supported by this reader")

        previous = None
        while previous != text:  # nested: $(var x) may yield a $(find-pkg-share ...)
            previous, text = text, _SUBSTITUTION.sub(one, text)
        if "$(" in text:
            raise LaunchFileError(f"{path.name}: cannot substitute {text!r}")
        return text


def _is_declaration(root: ET.Element, arg: ET.Element) -> bool:
    """True for an ``<arg>`` that declares a launch argument (a direct child of ``<launch>`` or of a group), not
    one passed to an ``<include>``."""
    parents = {child: parent for parent in root.iter() for child in parent}
    return parents.get(arg) is not None and parents[arg].tag in ("launch", "group")


def _required(el: ET.Element, attr: str, path: Path) -> str:
    value = el.get(attr)
    if value is None:
        raise LaunchFileError(f"{path.name}: <{el.tag}> without {attr}=")
    return value


def _only(el: ET.Element, allowed: set[str], path: Path) -> None:
    extra = sorted(set(el.attrib) - allowed)
    if extra:
        raise LaunchFileError(f"{path.name}: <{el.tag}> attribute(s) {', '.join(extra)} not supported by this reader")


def _typed(value: str):
    """A ``<param value>`` typed as ``launch_ros`` types it (YAML scalar; an empty string stays a string)."""
    if value == "":
        return ""
    try:
        typed = yaml.safe_load(value)
    except yaml.YAMLError:
        return value
    if isinstance(typed, (bool, int, float, str)):
        return typed
    if isinstance(typed, list) and typed and len({type(v) for v in typed}) == 1 \
            and isinstance(typed[0], (bool, int, float, str)):
        return typed
    return value
