"""The live monitor in a real browser (issue #20; the bench in tests/_monitor_page.py): the page
clicks "LOE 50 %" then "drift 0.8" (the emulator answers "applied"), and the page's k̂ and active
models must follow: k̂_LOE → 0.5 with an active spool model of θ ≈ 0.5, then k̂_DFT → 0.8 with
an active position model of θ ≈ 0.8. A screenshot is saved (its path printed). Waits have
generous limits only; nothing is timed.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from _monitor_page import (
    PAGE_MARKS,
    Monitored,
    browser,
    monitored_bench,
    number,
    theta,
    until,
    until_controlling,
)
from _proc import ROOT

pytestmark = PAGE_MARKS
SCREENSHOT = ROOT / "out" / "monitor-browser.png"


@pytest.fixture
def monitored(tmp_path: Path) -> Iterator[Monitored]:
    with monitored_bench(tmp_path) as m:
        yield m


@pytest.fixture
def bench(monitored: Monitored) -> str:
    return monitored.url


def test_fault_injected_from_the_page_reconfigures_the_controller(bench: str) -> None:
    from selenium.webdriver.common.by import By

    driver = browser()
    try:
        driver.get(bench)  # type: ignore[attr-defined]

        def text(elem_id: str) -> str:
            return str(driver.find_element(By.ID, elem_id).text)  # type: ignore[attr-defined]

        def click(kind: str) -> None:
            driver.find_element(By.CSS_SELECTOR, f'#inject button[data-kind="{kind}"]').click()  # type: ignore[attr-defined]

        until("mode mmac", lambda: text("mode") == "mmac")
        assert text("ref-note") == ""  # x_d and y_m aligned with the controller's reference
        until_controlling(
            "k̂_LOE 1 and k̂_DFT 1",
            lambda: number(text("k-loe-hat")) == 1.0 and number(text("k-dft-hat")) == 1.0,
            text,
            number(text("overruns")),
        )
        spool_before, pos_before = text("active-spool"), text("active-position")
        assert theta(spool_before) == pytest.approx(1.0, abs=0.01), spool_before
        assert theta(pos_before) == pytest.approx(1.0, abs=0.01), pos_before

        overruns0 = number(text("overruns"))
        click("k_loe")
        until("the inject applied", lambda: text("inject-result") == "applied by the emulator: k_loe = 0.5")
        until("true k_LOE 0.5", lambda: text("k-true").startswith("0.500"))
        until_controlling(
            "k̂_LOE ≈ 0.5", lambda: abs(number(text("k-loe-hat")) - 0.5) <= 0.05, text, overruns0
        )
        until("an active spool model with θ ≈ 0.5", lambda: abs(theta(text("active-spool")) - 0.5) <= 0.05)
        assert text("active-spool") != spool_before

        overruns0 = number(text("overruns"))
        click("k_dft")
        until("true k_DFT 0.8", lambda: text("k-true").endswith("0.800"))
        until_controlling(
            "k̂_DFT ≈ 0.8", lambda: abs(number(text("k-dft-hat")) - 0.8) <= 0.05, text, overruns0
        )
        until(
            "an active position model with θ ≈ 0.8",
            lambda: abs(theta(text("active-position")) - 0.8) <= 0.05,
        )
        assert abs(number(text("k-loe-hat")) - 0.5) <= 0.05  # the spool channel keeps its estimate
        until("the page refreshing", lambda: number(text("refresh-rate")) > 0)
        time.sleep(1.0)  # a full plot window after the drift, for the screenshot only
        driver.execute_script("window.scrollTo(0, 0)")  # type: ignore[attr-defined]
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(SCREENSHOT))  # type: ignore[attr-defined]
        print(f"\nmonitor screenshot: {SCREENSHOT} (page refresh {text('refresh-rate')} Hz)")
    finally:
        driver.quit()  # type: ignore[attr-defined]
