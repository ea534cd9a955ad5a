"""The set-up page's camera view over HTTP (urllib on loopback, the mock camera): the snapshot shows the region
of interest, and a quality engineer sets it in a form, checked, written to the camera file in one step, audited."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from service.publish.web.auth import User, hash_password, save_users
from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web import Client

CAMERA_FILE = """# the bench's camera: a tag on the pendulum (kept comment)
[camera]
width = 640
height = 480
fps = 60.0

[target]
kind = "tag"   # the printed tag
"""


def login(url: str, name: str, password: str) -> tuple[Client, str]:
    c = Client(url)
    status, _, page = c.request("/login", {"user": name, "token": password, "csrf": c.csrf(), "next": "/setup"})
    assert status == 200 and f"{name} (" in page.decode()
    return c, page.decode().split('name="csrf-token" content="')[1].split('"')[0]


def decoded(png: bytes) -> np.ndarray:
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None, "not a PNG"
    return img


def pixels(img: np.ndarray, bgr: tuple[int, int, int]) -> int:
    return int(np.count_nonzero((img == bgr).all(axis=2)))


def test_a_quality_engineer_sets_the_region_of_interest_an_operator_cannot(appliance_factory, tmp_path):
    cam = tmp_path / "cam.toml"
    cam.write_text(CAMERA_FILE, encoding="utf-8")
    users = tmp_path / "users.toml"
    save_users(users, {"olga": User("olga", "operator", hash_password("olga-password-1")),
                       "quinn": User("quinn", "quality", hash_password("quinn-password-2"))})
    running = appliance_factory(appliance_doc(tmp_path / "state", time_scale=1.0,
                                              web={"enabled": True, "users_file": str(users)},
                                              simulation={"sensor": "camera", "camera": str(cam)}))
    app = running.app
    url = app.web.url
    page = Client(url).request("/setup")[2].decode()
    assert "the whole frame" in page and 'id="roi-form"' not in page  # seen by all, set by no one logged out
    olga, ocsrf = login(url, "olga", "olga-password-1")
    assert 'id="roi-form"' not in olga.request("/setup")[2].decode()
    status, _, body = olga.request("/setup/roi", {"x": "200", "y": "200", "w": "240", "h": "240", "csrf": ocsrf})
    assert status == 403 and b"may not set the camera" in body and cam.read_text() == CAMERA_FILE

    quinn, qcsrf = login(url, "quinn", "quinn-password-2")
    assert 'id="roi-form"' in quinn.request("/setup")[2].decode()
    # a region off the image is refused beside the form, with what was typed; the file is unchanged
    status, _, body = quinn.request("/setup/roi", {"x": "500", "y": "200", "w": "240", "h": "240", "csrf": qcsrf})
    page = body.decode()
    assert status == 400 and "x + w = 740" in page and 'id="roi-error"' in page and 'value="500"' in page
    assert cam.read_text() == CAMERA_FILE and not (app.config.state_dir / "camera-audit.log").exists()
    status, _, body = quinn.request("/setup/roi", {"x": "2O0", "y": "200", "w": "240", "h": "240", "csrf": qcsrf})
    assert status == 400 and b"x: expected a whole number of pixels" in body

    # the tag swings below the pivot: a region over the lower part of the frame holds all of its swing
    status, _, body = quinn.request("/setup/roi", {"x": "40", "y": "140", "w": "560", "h": "340", "csrf": qcsrf})
    assert status == 200 and "x 40, y 140, w 560, h 340 px" in body.decode()  # after the redirect to /setup
    text = cam.read_text()
    assert "roi = [40, 140, 600, 480]" in text and "(kept comment)" in text and "# the printed tag" in text
    audit = (app.config.state_dir / "camera-audit.log").read_text().splitlines()
    assert len(audit) == 1 and "\tweb:quinn\t" in audit[0] and audit[0].endswith("roi: whole frame → [40, 140, 600, 480]")
    # the running camera uses it at once: the snapshot draws the new region (yellow) around the tag it found; the
    # simulated rig's wrapper forwards to the camera sensor, which tracks the next capture in it
    assert app.devices.sensor._inner.config.target.roi == (40, 140, 600, 480)
    assert app.config.simulation.camera_config.target.roi == (40, 140, 600, 480)
    status, headers, png = quinn.request("/setup/snapshot.png")
    assert status == 200 and headers["Content-Type"] == "image/png"
    img = decoded(png)
    yellow = (img == (0, 255, 255)).all(axis=2)
    assert yellow[300, 40] and yellow[300, 599] and yellow[140, 300] and yellow[479, 300] and not yellow[300, 20]
    assert pixels(img, (0, 0, 255)) > 20 and pixels(img, (0, 255, 0)) > 20  # the tag found (red), its axis (green)

    # all four empty: the whole frame again
    status, _, body = quinn.request("/setup/roi", {"x": "", "y": "", "w": "", "h": "", "csrf": qcsrf})
    assert status == 200 and "roi" not in cam.read_text().split("[target]")[1].split("#")[0]
    assert app.devices.sensor._inner.config.target.roi is None


def test_the_demo_camera_has_no_file_to_set_a_region_in(appliance_factory, tmp_path):
    running = appliance_factory(appliance_doc(tmp_path / "state", time_scale=1.0, web={"enabled": True},
                                              simulation={"sensor": "camera"}))
    app = running.app
    token = Path(app.web.token_file).read_text().strip()
    c = Client(app.web.url)
    status, _, page = c.request("/login", {"token": token, "next": "/setup", "csrf": c.csrf()})
    html = page.decode()
    assert status == 200 and "the demo camera: no camera file" in html and 'id="roi-form"' not in html
    csrf = html.split('name="csrf-token" content="')[1].split('"')[0]
    status, _, body = c.request("/setup/roi", {"x": "0", "y": "0", "w": "64", "h": "64", "csrf": csrf})
    assert status == 409 and b"the demo camera has no camera file" in body
    assert not (app.config.state_dir / "camera-audit.log").exists()
