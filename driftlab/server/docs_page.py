"""/docs: FastAPI's Swagger UI page with its bundle pinned. FastAPI's own page loads ``swagger-ui-dist@5`` (whatever
5.x jsDelivr serves that day) with no integrity check; here one version is named and each file carries its
Subresource Integrity hash, so a browser refuses a file the CDN changed. The hashes are those of the files in the
npm registry's tarball of that version, after checking the tarball against the registry's own sha512:
``python requirements/pin_swagger_ui.py 5.35.0`` prints them (jsDelivr serves npm files unchanged).
"""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse

SWAGGER_UI_VERSION = "5.35.0"
_CDN = f"https://cdn.jsdelivr.net/npm/swagger-ui-dist@{SWAGGER_UI_VERSION}"
SCRIPT = (f"{_CDN}/swagger-ui-bundle.js", "sha384-gjRm0bEPMeTmMh5jT2cHccIwCUZSTd8YC+j0d0sXw0MdGEfScduGpSyF3ZSSLkX9")
STYLE = (f"{_CDN}/swagger-ui.css", "sha384-WlYgdmXYOOBWL5apwjDEZwN+U3HmXSSu5R6V5aGxEcf7z+KuRNwBhoxKVN1i3D5I")


def pinned_swagger_page(openapi_url: str, title: str) -> str:
    """FastAPI's page with the pinned files and their integrity (ValueError if FastAPI's markup moved)."""
    html = get_swagger_ui_html(openapi_url=openapi_url, title=title, swagger_js_url=SCRIPT[0],
                               swagger_css_url=STYLE[0], swagger_favicon_url="data:,").body.decode()
    pinned = (html.replace(f'src="{SCRIPT[0]}"', f'src="{SCRIPT[0]}" integrity="{SCRIPT[1]}" crossorigin="anonymous"')
              .replace(f'href="{STYLE[0]}"', f'href="{STYLE[0]}" integrity="{STYLE[1]}" crossorigin="anonymous"'))
    if pinned.count("integrity=") != 2:
        raise ValueError("FastAPI's Swagger page no longer names its files as expected")
    return pinned


def add_docs_page(app: FastAPI) -> None:
    """The app must be made with ``docs_url=None`` (and ``redoc_url=None``: ReDoc's bundle is not pinned)."""
    page = pinned_swagger_page(app.openapi_url or "/openapi.json", f"{app.title} - API")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return HTMLResponse(page)
