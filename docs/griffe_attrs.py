"""A griffe extension for the API pages: the parameters of an attrs class's generated __init__,
read from its fields, so the pages show each field's default (a ``factory`` as the value it
makes) instead of calling every field required. Static: it reads the source, imports nothing."""

from __future__ import annotations

import griffe

_ATTRS_DECORATORS = ("attrs.frozen", "attrs.define", "attrs.mutable", "attr.s", "attrs.s")
_FACTORIES = {"dict": "{}", "list": "[]", "tuple": "()", "set": "set()"}


class AttrsInit(griffe.Extension):
    def on_class_members(self, *, cls: griffe.Class, **kwargs) -> None:
        decorators = [str(d.value) for d in cls.decorators]
        if "__init__" in cls.members or not any(d.startswith(_ATTRS_DECORATORS) for d in decorators):
            return
        keyword_only = any("kw_only=True" in d for d in decorators)
        kind = griffe.ParameterKind.keyword_only if keyword_only else griffe.ParameterKind.positional_or_keyword
        parameters = [griffe.Parameter("self", kind=griffe.ParameterKind.positional_or_keyword)]
        for member in cls.members.values():
            if not member.is_attribute or member.annotation is None or "class-attribute" not in member.labels:
                continue
            taken, default = _field(member.value)
            if taken:
                parameters.append(
                    griffe.Parameter(member.name, annotation=member.annotation, kind=kind, default=default)
                )
        cls.set_member("__init__", griffe.Function("__init__", parameters=griffe.Parameters(*parameters)))


def _field(value) -> tuple[bool, object]:
    """Whether __init__ takes a field whose class-level value is `value`, and its default (None
    where it has none: the pages then say required)."""
    if value is None:
        return True, None
    if not isinstance(value, griffe.ExprCall) or not str(value.function).endswith("field"):
        return True, value
    keywords = {str(a.name): a.value for a in value.arguments if isinstance(a, griffe.ExprKeyword)}
    if str(keywords.get("init", "True")) == "False":
        return False, None
    if "default" in keywords:
        return True, keywords["default"]
    if "factory" in keywords:
        factory = str(keywords["factory"])
        return True, _FACTORIES.get(factory, f"{factory}()")
    return True, None
