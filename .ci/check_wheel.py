"""Build the wheel and import every subpackage from it, not from the source tree.

An editable install imports whatever is in the tree, so a subpackage that the packaging
drops would go unnoticed there; this check fails on it.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("opa", "mc", "compare")


def source_packages() -> list[str]:
    """Every folder of the three packages that holds Python files (each must be a package)."""
    folders = sorted({p.parent for top in PACKAGES for p in (ROOT / top).rglob("*.py")
                      if "__pycache__" not in p.parts})
    bare = [str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").exists()]
    if bare:
        raise SystemExit(f"check_wheel: {', '.join(bare)} hold Python files but no __init__.py")
    return [".".join(f.relative_to(ROOT).parts) for f in folders]


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                        "-q", "-w", str(tmp), str(ROOT)], check=True)
        wheel = next(tmp.glob("opa_mc-*.whl"))
        names = set(zipfile.ZipFile(wheel).namelist())
        packages = source_packages()
        missing = [p for p in packages if p.replace(".", "/") + "/__init__.py" not in names]
        if missing:
            print(f"check_wheel: {wheel.name} lacks {', '.join(missing)}", file=sys.stderr)
            return 1
        site = tmp / "site"
        subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target",
                        str(site), str(wheel)], check=True)
        code = ("import importlib, sys\n"
                f"for name in {packages!r}:\n"
                "    module = importlib.import_module(name)\n"
                f"    assert module.__file__.startswith({str(site)!r}), (name, module.__file__)\n"
                "print('imported', len(sys.modules), 'modules')\n")
        subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp,
                       env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"})
        print(f"check_wheel: {wheel.name} holds and imports {len(packages)} packages: "
              f"{', '.join(packages)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
