"""ROS 2 parameter YAML read as rcl reads it (rcl_yaml_param_parser's get_value), so that a
value the replay accepts is the value fcop_node would get: '1_000', '2024-01-01' and '٣' are
text to rcl, '010' is 8, '08' is 8.0 and 'yes' is true, whatever YAML 1.1 or Python say."""

from __future__ import annotations

import difflib
import math
import re

import yaml

_STR_TAG = "tag:yaml.org,2002:str"
_PLAIN = "!plain"  # the tag of every untagged node, so that an explicit !!str stands apart
_BOOL = {
    **dict.fromkeys("Y y yes Yes YES true True TRUE on On ON".split(), True),
    **dict.fromkeys("N n no No NO false False FALSE off Off OFF".split(), False),
}
_YAML_SPECIAL = {
    f"{sign}.{word}": float(f"{sign}{word}")
    for sign in ("", "+", "-") for word in ("inf", "Inf", "INF")
} | {f".{word}": float("nan") for word in ("nan", "NaN", "NAN")}
_SPACE = r"[ \t\n\v\f\r]*"
# strtoll(text, &end, 0) consuming all of text: C's decimal, octal and hex, ASCII digits only.
_C_INTEGER = re.compile(_SPACE + r"([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
# strtod consuming all of text in the C locale.
_C_DOUBLE = re.compile(_SPACE + r"""[+-]?(?:
      (?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?
    | 0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?
    | (?i:inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?))""", re.X)
_SMALLEST_NORMAL = 2.2250738585072014e-308


class RclYamlError(ValueError):
    """YAML that parses but that rcl refuses (no value, a sequence of mixed types, ...)."""


def _c_integer(text: str):
    m = _C_INTEGER.fullmatch(text)
    if m is None:
        return None
    sign, digits = m.groups()
    if digits[:2] in ("0x", "0X"):
        value = int(digits[2:], 16)
    elif digits[0] == "0":
        value = int(digits, 8)
    else:
        value = int(digits)
    value = -value if sign == "-" else value
    return value if -2**63 <= value < 2**63 else None  # ERANGE: rcl tries a double


def _c_double(text: str):
    if text in _YAML_SPECIAL:
        return _YAML_SPECIAL[text]
    if _C_DOUBLE.fullmatch(text) is None:
        return None
    body = text.lstrip(" \t\n\v\f\r").lower()
    unsigned = body.lstrip("+-")
    if unsigned.startswith(("inf", "nan")):
        return float(body.split("(")[0])
    if unsigned.startswith("0x"):
        value, mantissa = float.fromhex(body), unsigned[2:].split("p")[0]
    else:
        value, mantissa = float(body), unsigned.split("e")[0]
    if math.isinf(value) or 0 < abs(value) < _SMALLEST_NORMAL or (
            value == 0 and mantissa.strip("0.")):
        return None  # ERANGE (overflow, underflow, a subnormal): rcl keeps the text
    return value


def scalar(text: str, quoted: bool = False, str_tag: bool = False):
    """One scalar typed as rcl types it: a bool word, a C integer (int64), a C double or
    YAML's .inf/.nan, else text; quoted or tagged !!str it is text."""
    if quoted or str_tag:
        return text
    if text in _BOOL:
        return _BOOL[text]
    for convert in (_c_integer, _c_double):
        value = convert(text)
        if value is not None:
            return value
    return text


class _Loader(yaml.BaseLoader):
    """Composes nodes without YAML 1.1's implicit types (untagged nodes get _PLAIN) and
    refuses aliases, as rcl does."""

    def resolve(self, kind, value, implicit):
        return _PLAIN

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            line = self.peek_event().start_mark.line + 1
            raise RclYamlError(f"an alias (*name) at line {line}: rcl does not take aliases")
        return super().compose_node(parent, index)


def _value(node, where: str):
    if isinstance(node, yaml.ScalarNode):
        if node.style not in ("'", '"') and node.value == "":
            raise RclYamlError(f"{where} has no value (line {node.start_mark.line + 1})")
        return scalar(node.value, quoted=node.style in ("'", '"'), str_tag=node.tag == _STR_TAG)
    if isinstance(node, yaml.SequenceNode):
        items = [_value(item, where) for item in node.value]
        if not items:  # rcl leaves the parameter unset
            raise RclYamlError(f"{where} has no value (line {node.start_mark.line + 1})")
        if any(not isinstance(item, (bool, int, float, str)) for item in items):
            raise RclYamlError(f"{where}: a sequence may hold only values, not sequences "
                               f"or mappings (line {node.start_mark.line + 1})")
        if len({type(item) for item in items}) > 1:
            raise RclYamlError(f"{where}: a sequence's values must be of one type, as rcl "
                               f"requires (line {node.start_mark.line + 1})")
        return items
    return {
        key.value: _value(item, f"{where}/{key.value}" if where else key.value)
        for key, item in node.value
    }


def parameter_entries(text: str) -> list:
    """(section, parameter name, value) of every parameter of a ROS 2 params file, in the order
    rcl applies them: file order, document after document, a later value winning (sections
    of the same node are merged, not replaced). Nested mappings under ros__parameters give
    dotted names. yaml.YAMLError if it is not YAML, RclYamlError for a structure rcl refuses
    or a value it would not take."""
    out = []
    for root in yaml.compose_all(text, Loader=_Loader):
        if root is None:
            continue
        if not isinstance(root, yaml.MappingNode):
            raise RclYamlError("it is not a ROS 2 parameter file (expected '/**:' or a node "
                               "name, with 'ros__parameters:' under it)")
        _sections(root, "", out)
    return out


def _sections(node, prefix: str, out: list) -> None:
    for key, body in node.value:
        full = f"{prefix}{key.value}"
        if not isinstance(body, yaml.MappingNode):
            raise RclYamlError(_outside_ros_parameters(prefix, key))
        keys = [k.value for k, _ in body.value]
        if "ros__parameters" not in keys:
            _sections(body, full.rstrip("/") + "/", out)
            continue
        for k, params in body.value:
            if k.value != "ros__parameters":
                raise RclYamlError(f"section {full!r}: {k.value!r} stands beside "
                                   "ros__parameters, which rcl refuses")
            if not isinstance(params, yaml.MappingNode):
                raise RclYamlError(f"section {full!r}: ros__parameters is not a mapping")
            _parameters(params, full, "", out)


_LAYOUT = "'/**:' (or the node's name), then 'ros__parameters:', then the parameters"


def _outside_ros_parameters(prefix: str, key) -> str:
    """The message for a value met above any ros__parameters: the section lacks it (or spells
    it wrong), which rcl refuses."""
    parts = prefix.rstrip("/").split("/")
    for i, part in enumerate(parts):
        if difflib.get_close_matches(part, ["ros__parameters"], cutoff=0.8):
            owner = f"section {'/'.join(parts[:i])!r}" if i else "the file"
            return f"{owner} has no ros__parameters (did you mean ros__parameters for {part!r}?)"
    section = "/".join(parts)
    at = f"{key.value!r} (line {key.start_mark.line + 1})"
    if not section:
        return f"{at} is outside any section's ros__parameters: the layout is {_LAYOUT}"
    return (f"section {section!r} has no ros__parameters, so {at} is outside it: the layout is "
            f"{_LAYOUT}")


def _parameters(node, section: str, prefix: str, out: list) -> None:
    for key, item in node.value:
        name = f"{prefix}{key.value}"
        if isinstance(item, yaml.MappingNode):
            _parameters(item, section, f"{name}.", out)
        else:
            out.append((section, name, _value(item, name)))


def load(text: str, where: str = ""):
    """A YAML document of dicts, lists and rcl-typed scalars (None for an empty document);
    yaml.YAMLError if it is not YAML, RclYamlError if rcl would refuse it."""
    node = yaml.compose(text, Loader=_Loader)
    return None if node is None else _value(node, where)
