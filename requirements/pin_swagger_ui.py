"""Print the Subresource Integrity hashes of swagger-ui-dist's bundle and stylesheet for one version, for
driftlab/server/docs_page.py: from the npm registry's tarball, checked against the registry's sha512 first.

    python requirements/pin_swagger_ui.py 5.35.0
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import sys
import tarfile
import urllib.request

FILES = ("swagger-ui-bundle.js", "swagger-ui.css")


def main(version: str) -> None:
    with urllib.request.urlopen(f"https://registry.npmjs.org/swagger-ui-dist/{version}", timeout=60) as answer:
        dist = json.load(answer)["dist"]
    with urllib.request.urlopen(dist["tarball"], timeout=120) as answer:
        tarball = answer.read()
    algorithm, _, expected = dist["integrity"].partition("-")
    if base64.b64encode(hashlib.new(algorithm, tarball).digest()).decode() != expected:
        raise SystemExit(f"the tarball of swagger-ui-dist {version} does not match the registry's {algorithm}")
    with tarfile.open(fileobj=io.BytesIO(tarball)) as archive:
        for name in FILES:
            data = archive.extractfile(f"package/{name}").read()
            print(name, "sha384-" + base64.b64encode(hashlib.sha384(data).digest()).decode())


if __name__ == "__main__":
    main(sys.argv[1])
