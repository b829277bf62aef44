"""The web panel in a real browser: Debian's headless Chromium, driven by selenium, against a
real cncd on the sim card. Loads the panel, uploads a program, starts it, sees the DRO and the
live tool move, holds, resumes, sees it done; the e-stop latches; a continuous jog stops when
the button is released and when the page is closed. PANEL_SCREENSHOTS=DIR keeps the
screenshots there (`docs/panel.png`, `docs/panel-running.png`)."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("aiohttp")
webdriver = pytest.importorskip("selenium.webdriver")

from daemon_helpers import REPO  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from web_helpers import web_cncd  # noqa: E402

from controller.operator.client import DaemonClient  # noqa: E402

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
pytestmark = pytest.mark.skipif(
    not (os.access(CHROMIUM, os.X_OK) and os.access(CHROMEDRIVER, os.X_OK)),
    reason="needs Debian's chromium and chromium-driver (apt install chromium chromium-driver)")


def browser() -> Any:
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--window-size=1280,1000", "--disable-gpu"):
        options.add_argument(arg)
    return webdriver.Chrome(options=options,
                            service=webdriver.ChromeService(executable_path=CHROMEDRIVER))


@pytest.fixture
def panel(tmp_path: Path) -> Iterator[tuple[Any, Any, str]]:
    with web_cncd(tmp_path) as (daemon, base):
        driver = browser()
        try:
            driver.get(base + "/")
            yield driver, daemon, base
        finally:
            driver.quit()


def until(what: Callable[[], Any], timeout_s: float = 20.0,
          why: str | Callable[[], str] = "") -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = what()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"not within {timeout_s} s: {why() if callable(why) else why}")


def panel_says(driver: Any) -> str:
    return (f"state {text(driver, 'state')}, message {text(driver, 'message')!r}, "
            f"{text(driver, 'conn')}, log {text(driver, 'log')[:300]!r}")


def text(driver: Any, element_id: str) -> str:
    return driver.find_element(By.ID, element_id).text


def state_is(driver: Any, *states: str) -> Callable[[], bool]:
    return lambda: text(driver, "state") in states


def screenshot(driver: Any, name: str, tmp_path: Path) -> None:
    path = tmp_path / name
    driver.save_screenshot(str(path))
    keep = os.environ.get("PANEL_SCREENSHOTS")
    if keep:
        shutil.copy(path, Path(keep) / name)


def test_upload_run_hold_resume_done_and_estop(panel: tuple[Any, Any, str],
                                               tmp_path: Path) -> None:
    driver, daemon, _ = panel
    until(state_is(driver, "ESTOP"), why="the panel shows the daemon's state")
    driver.find_element(By.ID, "reset").click()
    until(state_is(driver, "IDLE"), why="reset")
    driver.find_element(By.ID, "upload-file").send_keys(
        str(REPO / "nc_programs" / "naca2415.nc"))
    driver.find_element(By.ID, "upload-btn").click()
    run = until(lambda: driver.find_elements(By.CSS_SELECTOR, "button[data-run='naca2415.nc']"),
                why="the uploaded program listed")[0]
    # a slower run (10 % override, through the slider) to see it move, hold and resume
    driver.execute_script("const o = document.getElementById('override'); o.value = 10;"
                          "o.dispatchEvent(new Event('change'));")
    until(lambda: status(daemon)["feed_override_pct"] == 10.0, why="override")
    run.click()
    until(state_is(driver, "RUNNING"), why="the job runs")
    first = (text(driver, "dro-wx"), driver.find_element(By.ID, "preview").get_attribute(
        "data-tool"))
    until(lambda: text(driver, "dro-wx") != first[0], why="the DRO moves")
    until(lambda: driver.find_element(By.ID, "preview").get_attribute("data-tool") != first[1],
          why="the live tool moves on the preview")
    until(lambda: int(driver.find_element(By.ID, "preview").get_attribute("data-cut")) > 5,
          why=lambda: f"the part cut so far drawn apart (the tool's trail; {panel_says(driver)})")
    screenshot(driver, "panel-running.png", tmp_path)
    driver.find_element(By.ID, "hold").click()
    until(state_is(driver, "HELD"), why=lambda: f"held ({panel_says(driver)})")
    held = text(driver, "dro-wx")
    time.sleep(0.5)
    assert text(driver, "dro-wx") == held, "the DRO moved while held"
    driver.find_element(By.ID, "resume").click()
    until(state_is(driver, "IDLE"), timeout_s=60,
          why=lambda: f"the job ends ({panel_says(driver)}, {status(daemon)['state']})")
    until(lambda: "naca2415.nc: done" in text(driver, "message"), why="done is said")
    assert daemon.status()["last_job"]["state"] == "DONE"
    driver.execute_script("const o = document.getElementById('override'); o.value = 100;"
                          "o.dispatchEvent(new Event('change'));")
    screenshot(driver, "panel.png", tmp_path)
    driver.find_element(By.ID, "estop").click()
    until(state_is(driver, "ESTOP"), why="e-stop")
    time.sleep(0.5)
    assert text(driver, "state") == "ESTOP", "the e-stop did not latch"
    assert "latched" in driver.find_element(By.ID, "estop").get_attribute("class")
    assert daemon.status()["drives"] == "disabled"


def status(daemon: Any) -> dict[str, Any]:
    """The daemon's status straight from its socket (a cncctl process costs 0.5 s or more)."""
    with DaemonClient(daemon.socket_path) as client:
        return client.request("status")


def _x_mm(daemon: Any) -> float:
    return status(daemon)["position_mm"]["x"]


def test_continuous_jog_stops_on_release_and_when_the_page_closes(
        panel: tuple[Any, Any, str]) -> None:
    driver, daemon, _ = panel
    until(state_is(driver, "ESTOP"))
    driver.find_element(By.ID, "reset").click()
    until(state_is(driver, "IDLE"))
    driver.execute_script("document.getElementById('jog-step').value = 'cont';")
    button = driver.find_element(By.CSS_SELECTOR, ".jog[data-axis='x'][data-dir='1']")
    for close_page in (False, True):
        start = _x_mm(daemon)
        ActionChains(driver).click_and_hold(button).perform()
        until(lambda: _x_mm(daemon) > start + 0.5, why="the jog moves while pressed")  # noqa: B023
        if close_page:
            driver.quit()  # the page closed: its WebSocket drops
        else:
            ActionChains(driver).release(button).perform()
        released_s = time.monotonic()
        until(lambda: status(daemon)["state"] == "IDLE", timeout_s=5, why="the jog stops")
        took_s = time.monotonic() - released_s
        stopped = _x_mm(daemon)
        time.sleep(0.5)
        assert _x_mm(daemon) == stopped
        assert took_s < 2.0, took_s  # the jog's own time-out would be 60 s
