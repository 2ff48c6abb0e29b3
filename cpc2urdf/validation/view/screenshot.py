"""A PNG screenshot of a page (a view's static HTML or a served view) in headless Chromium."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

from cpc2urdf.errors import ConfigurationError, InputFileError, OutputError

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
)
NO_NETWORK_FLAG = (
    "--host-resolver-rules=MAP * ~NOTFOUND"  # for files: the page must not need a network
)


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable (``$CPC2URDF_CHROMIUM`` first), or None."""
    env = os.environ.get("CPC2URDF_CHROMIUM")
    if env:
        return env if Path(env).is_file() else shutil.which(env)
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot_html(
    page: str | os.PathLike[str],
    png_path: str | os.PathLike[str],
    *,
    size: tuple[int, int] = (1024, 768),
    budget_ms: int = 2000,
    timeout: float = 120.0,
) -> Path:
    """Render a page in headless Chromium (software WebGL) and save a PNG screenshot.

    Args:
        page: The page file (e.g. from :func:`write_view_html`), or an ``http://`` URL (a served
            view; the static page needs no network, and Chromium is kept from resolving names).
        png_path: The PNG to write.
        size: Window width and height [px].
        budget_ms: Chromium's virtual time budget for the page to load and render [ms].
        timeout: Give up after this long [s] (the browser never waits for a user).

    Raises:
        InputFileError: The page file does not exist.
        OutputError: No Chromium found (install Debian's ``chromium``), it failed or timed out,
            or the PNG's folder does not exist.
    """
    exe = find_chromium()
    if exe is None:
        raise OutputError(
            "no Chromium found: install it (apt-get install chromium) or set CPC2URDF_CHROMIUM"
        )
    text = str(page)
    flags = list(CHROMIUM_FLAGS)
    if text.startswith(("http://", "https://")):
        url = text
    else:
        flags.append(NO_NETWORK_FLAG)
        html = Path(page).resolve()
        if not html.is_file():
            raise InputFileError(html, "no such file")
        url = html.as_uri()
    png = Path(png_path).resolve()
    if not png.parent.is_dir():
        raise OutputError(f"{png}: cannot write, folder {png.parent} does not exist")
    with tempfile.TemporaryDirectory(prefix="cpc2urdf-chromium-") as profile:
        tmp_png = Path(profile) / "shot.png"
        cmd = [
            exe,
            *flags,
            f"--user-data-dir={profile}/profile",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={budget_ms}",
            f"--screenshot={tmp_png}",
            url,
        ]
        # Its own process group, so that a timeout ends the browser and all its helpers.
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )
        try:
            _, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired as e:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise OutputError(f"{png}: Chromium did not finish within {timeout:.0f} s") from e
        if proc.returncode != 0 or not tmp_png.is_file():
            tail = (err.strip().splitlines() or ["no output"])[-1]
            raise OutputError(f"{png}: Chromium failed (exit {proc.returncode}): {tail}")
        shutil.move(str(tmp_png), str(png))
    return png


def screenshot_page(
    html_text: str,
    png_name: str | os.PathLike[str],
    *,
    size: tuple[int, int] = (1024, 768),
    budget_ms: int = 2000,
    timeout: float = 120.0,
) -> bytes:
    """The PNG bytes of a page given as text (:func:`screenshot_html` on a temporary copy), so a
    command can render before it writes anything: a failed screenshot leaves no page behind.
    Errors name ``png_name``, the PNG the caller will write.

    Raises:
        OutputError: As :func:`screenshot_html`.
    """
    with tempfile.TemporaryDirectory(prefix="cpc2urdf-page-") as folder:
        page = Path(folder) / "page.html"
        page.write_text(html_text, encoding="utf-8")
        shot = (Path(folder) / "page.png").resolve()
        try:
            return screenshot_html(
                page, shot, size=size, budget_ms=budget_ms, timeout=timeout
            ).read_bytes()
        except OutputError as e:
            raise OutputError(str(e).replace(str(shot), os.fspath(png_name))) from e


def require_chromium(option: str = "--screenshot") -> None:
    """:class:`ConfigurationError` naming ``option`` when no Chromium is found (checked before a
    long computation whose picture it would take)."""
    if find_chromium() is None:
        raise ConfigurationError(
            f"{option} needs Chromium, and none was found: install it (apt-get install "
            "chromium) or set CPC2URDF_CHROMIUM"
        )


__all__ = [
    "CHROMIUM_FLAGS",
    "NO_NETWORK_FLAG",
    "find_chromium",
    "require_chromium",
    "screenshot_html",
    "screenshot_page",
]
