"""The bridge's protocol reference, from its OpenAPI description
(``noisebo.bridge.server.make_app(...).openapi()``): every path with its parameters, request body
and answers, then every body's fields with their types, units and meaning."""

from __future__ import annotations

import json
import re

from generate.markdown import code, paragraphs, table

KINDS = {
    "number": "number",
    "integer": "whole number",
    "string": "text",
    "boolean": "true or false",
    "object": "object",
    "null": "null",
}
LIMITS = (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<"))


def anchor(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def limits(schema: dict) -> list[str]:
    said = [f"{sign} {schema[key]:g}" for key, sign in LIMITS if key in schema]
    said += [f"at least {schema['minLength']} long"] if "minLength" in schema else []
    said += [f"at most {schema['maxLength']} long"] if "maxLength" in schema else []
    return said


def type_text(schema: dict) -> str:
    """A JSON schema's type in words; a named schema is a link to its section."""
    if "$ref" in schema:
        name = ref_name(schema["$ref"])
        return f"[{name}](#{anchor(name)})"
    members = schema.get("anyOf") or schema.get("oneOf")
    if members:
        named = [type_text(m) for m in members if m.get("type") != "null"]
        return " or ".join(named) + (", or null" if any(m.get("type") == "null" for m in members) else "")
    if "const" in schema:
        text = code(json.dumps(schema["const"]))
    elif "enum" in schema:
        text = "one of " + ", ".join(code(json.dumps(v)) for v in schema["enum"])
    elif schema.get("type") == "array":
        text = f"list of {type_text(schema.get('items', {}))}"
    else:
        text = KINDS.get(schema.get("type", ""), "any")
    said = limits(schema)
    return f"{text} ({', '.join(said)})" if said else text


def fields_table(schema: dict) -> str:
    required = set(schema.get("required", ()))
    rows = []
    for name, field in schema.get("properties", {}).items():
        given = (
            "required"
            if name in required
            else (code(json.dumps(field["default"])) if "default" in field else "optional")
        )
        rows.append((code(name), type_text(field), given, field.get("description", "")))
    return table(["field", "type", "default", "meaning"], rows)


def parameters_table(parameters: list[dict]) -> str:
    rows = []
    for p in parameters:
        schema = p.get("schema", {})
        given = "required" if p.get("required") else code(json.dumps(schema.get("default")))
        rows.append((code(p["name"]), p["in"], type_text(schema), given, p.get("description", "")))
    return table(["parameter", "in", "type", "default", "meaning"], rows)


def body_of(content: dict) -> str:
    schema = content.get("application/json", {}).get("schema", {})
    if not schema:
        return ""
    return (
        type_text(schema)
        if "$ref" in schema or "anyOf" in schema
        else f"[{schema['title']}](#{anchor(schema['title'])})"
    )


def operation_section(method: str, path: str, op: dict) -> str:
    parts = [f"### `{method.upper()} {path}`\n", f"{op.get('summary', '')}.\n", paragraphs(op.get("description"))]
    if op.get("parameters"):
        parts += ["**Parameters**\n", parameters_table(op["parameters"])]
    body = op.get("requestBody")
    if body:
        parts.append(f"**Body** ({'required' if body.get('required') else 'optional'}): {body_of(body['content'])}\n")
    rows = [
        (code(status), body_of(answer.get("content", {})), answer.get("description", ""))
        for status, answer in op.get("responses", {}).items()
    ]
    parts += ["**Answers**\n", table(["status", "body", "meaning"], rows)]
    return "\n".join(parts)


def schemas_of(api: dict) -> dict[str, dict]:
    """Every named body: the components, and the request bodies given whole (with their $defs)."""
    named = dict(api.get("components", {}).get("schemas", {}))
    for ops in api["paths"].values():
        for op in ops.values():
            schema = op.get("requestBody", {}).get("content", {}).get("application/json", {}).get("schema")
            if schema and "title" in schema:
                named[schema["title"]] = {k: v for k, v in schema.items() if k != "$defs"}
                named |= schema.get("$defs", {})
    return named


def api_description() -> dict:
    from noisebo.bridge.server import make_app

    return make_app(None, "", 1).openapi()  # the description needs neither an exchange nor the token


def page() -> str:
    """The generated part of the bridge's protocol page."""
    api = api_description()
    operations = [
        operation_section(method, path, op) for path, ops in api["paths"].items() for method, op in ops.items()
    ]
    bodies = [
        f"### {name} {{#{anchor(name)}}}\n\n{paragraphs(schema.get('description'))}\n{fields_table(schema)}"
        for name, schema in schemas_of(api).items()
    ]
    return "\n".join([f"API version {api['info']['version']}.\n", *operations, "## Bodies\n", *bodies])
