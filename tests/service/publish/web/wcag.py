"""The WCAG 2 contrast ratio of text as the browser shows it, for the pages' browser tests."""

from __future__ import annotations

import re


def contrast(driver, el) -> float:
    """The WCAG 2 contrast ratio of an element's text colour against its background: the first opaque background up
    the tree (the page's white when none is), both as the browser computed them."""
    fg, bg = driver.execute_script(r"""
        var fg = getComputedStyle(arguments[0]).color, bg = null;
        for (var n = arguments[0]; n && !bg; n = n.parentElement) {
          var c = getComputedStyle(n).backgroundColor, m = c.match(/rgba?\(([^)]*)\)/);
          var parts = m ? m[1].split(',').map(parseFloat) : [];
          if (parts.length >= 3 && (parts.length === 3 || parts[3] >= 1)) { bg = c; }
        }
        return [fg, bg || 'rgb(255, 255, 255)'];""", el)

    def luminance(css: str) -> float:
        r, g, b = (float(x) / 255 for x in re.findall(r"[\d.]+", css)[:3])
        lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in (r, g, b)]
        return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]

    a, b = sorted((luminance(fg), luminance(bg)), reverse=True)
    return (a + 0.05) / (b + 0.05)
