"""MkDocs hook (mkdocs.yml `hooks:`): the page schema.md gets the JSON Schema of the model language, as
`mechsys schema` prints it, in place of the line `<!-- json-schema -->`."""
from __future__ import annotations

import json


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != "schema.md":
        return markdown
    from mechsys.model.schema import json_schema

    text = json.dumps(json_schema(), indent=2)
    return markdown.replace("<!-- json-schema -->", f"```json\n{text}\n```")
