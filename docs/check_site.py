"""Open the built documentation site offline in a real browser (headless Chromium,
driven by Playwright) and check what a reader sees:

- formulas are rendered: every formula is a MathML element with a size, and no raw
  TeX (\\( \\) \\[ \\] $$ \\frac ...) is left in the text outside code;
- no block is cut off: a code block, notebook output, table or formula wider than
  its column scrolls sideways (its overflow is auto or scroll), and none reaches
  past the column's right edge;
- the notebooks' pages show no raw progress-bar text ("100%|", "4.04it/s]");
- the task index ("How do I ...") is reached from the home page by a link;
- the site asks for nothing outside this machine: it is served from a local HTTP
  server on 127.0.0.1, and every request to another host is refused and reported.

    mkdocs build --strict --site-dir SITE
    python docs/check_site.py SITE [--chromium PATH] [--screenshots DIR]

Needs `pip install playwright` and a Chromium: Playwright's own (`playwright install
chromium`) or the system's (Debian's `chromium` package; found on PATH, or named by
--chromium). Prints one line per problem and a summary; exits 1 on a problem.
"""

import argparse
import functools
import http.server
import shutil
import sys
import threading
from pathlib import Path
from urllib.parse import urlparse

#: Widths of the window: a desktop with both sidebars, a narrow laptop, a phone.
VIEWPORTS = {"desktop": (1280, 900), "laptop": (1000, 800), "phone": (390, 844)}
#: Raw TeX that a formula left unrendered shows.
RAW_TEX = r"\\\(|\\\)|\\\[|\\\]|\$\$|\\(frac|mathrm|nabla|tilde|begin)\b"
#: Raw text of a progress bar (tqdm's): "100%|", a rate "4.04trajectory/s]", "2.96s/it]".
PROGRESS = r"\d%\||\d(?:[A-Za-z]+/s|s/[A-Za-z]+)\]"

#: Run in the page: what it shows that should not be there.
PAGE_CHECK = """([rawTex, progress, isNotebook]) => {
  const problems = [], article = document.querySelector("article") || document.body;
  // the column: the content area (on a phone the theme lets code blocks reach the
  // screen's edges, past the article's margins, on purpose)
  const column = (document.querySelector(".md-content") || article).getBoundingClientRect();
  // raw TeX in the text, outside code, scripts and MathML
  const walker = document.createTreeWalker(article, NodeFilter.SHOW_TEXT);
  const tex = new RegExp(rawTex), bar = new RegExp(progress);
  for (let node; (node = walker.nextNode());) {
    if (node.parentElement.closest("pre, code, script, style, math, .jp-OutputArea")) continue;
    const m = node.textContent.match(tex);
    const text = node.textContent.trim().slice(0, 80);
    if (m) problems.push(`raw TeX ${JSON.stringify(m[0])} in "${text}"`);
  }
  // formulas: MathML elements that the browser laid out
  const maths = [...article.querySelectorAll("math")];
  for (const m of maths) {
    const r = m.getBoundingClientRect();
    if (!(r.width > 0 && r.height > 0))
      problems.push(`formula not laid out: ${m.textContent.slice(0, 60)}`);
  }
  // wide blocks: each one wider than its box scrolls, and none passes the column
  let wide = 0;
  const blocks = article.querySelectorAll(
    "pre, pre > code, table, math[display=block], .jp-OutputArea-output, .md-typeset__table");
  for (const el of blocks) {
    if (el.offsetParent === null) continue;  // hidden (a closed tab or details)
    const style = getComputedStyle(el), r = el.getBoundingClientRect();
    const scrolls = ["auto", "scroll"].includes(style.overflowX);
    if (el.scrollWidth > el.clientWidth + 1) {
      if (scrolls) wide += 1;
      else if (!el.parentElement.closest("pre, .md-typeset__table, math"))
        problems.push(`cut off: <${el.tagName.toLowerCase()} class="${el.className}"> ` +
                      `${el.scrollWidth}px of content in ${el.clientWidth}px, ` +
                      `overflow-x ${style.overflowX}`);
    }
    let scroller = el.parentElement;
    while (scroller && scroller !== article &&
           !["auto", "scroll"].includes(getComputedStyle(scroller).overflowX))
      scroller = scroller.parentElement;
    if (r.right > column.right + 1 && (!scroller || scroller === article))
      problems.push(`past the column: <${el.tagName.toLowerCase()}> ends at ` +
                    `${Math.round(r.right)}px, the column at ${Math.round(column.right)}px`);
  }
  // the page itself: nothing pushes it wider than the window
  if (document.documentElement.scrollWidth > window.innerWidth + 1)
    problems.push(`the page is ${document.documentElement.scrollWidth}px wide in a ` +
                  `${window.innerWidth}px window`);
  // progress bars in a notebook's outputs
  if (isNotebook) {
    for (const line of article.innerText.split("\\n")) {
      if (bar.test(line)) problems.push(`progress text: ${JSON.stringify(line.slice(0, 100))}`);
    }
  }
  return {problems, maths: maths.length, wide, blocks: blocks.length};
}"""


def serve(site: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    """A quiet HTTP server of `site` on 127.0.0.1, on a free port, in a thread."""

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    class Server(http.server.ThreadingHTTPServer):
        def handle_error(self, request, client_address):
            pass  # a page left before its last file arrived: a broken pipe

    server = Server(
        ("127.0.0.1", 0), functools.partial(Quiet, directory=str(site)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


def chromium_path(given: str | None) -> str | None:
    """The Chromium to launch: `given`, else None (Playwright's own) where Playwright
    has one installed, else the system's."""
    if given:
        return given
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        if Path(p.chromium.executable_path).exists():
            return None
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if found := shutil.which(name):
            return found
    sys.exit("no Chromium: run `playwright install chromium`, install Debian's "
             "chromium, or name one with --chromium")


def check(site: Path, chromium: str | None, screenshots: Path | None) -> int:
    from playwright.sync_api import sync_playwright

    pages = sorted(p.relative_to(site).as_posix() for p in site.rglob("index.html"))
    pages = [p for p in pages if not p.startswith(("assets/", "search/"))]
    server, root = serve(site)
    blocked, problems = [], []
    totals = {"pages": 0, "formulas": 0, "wide blocks that scroll": 0, "blocks": 0}
    with sync_playwright() as p:
        # scrollbars shown, as a reader's browser shows them (headless hides them)
        browser = p.chromium.launch(executable_path=chromium,
                                    ignore_default_args=["--hide-scrollbars"])
        print(f"browser: Chromium {browser.version} ({chromium or 'Playwright'})")

        def route(r):
            host = urlparse(r.request.url).hostname
            if host in ("127.0.0.1", "localhost"):
                r.continue_()
            else:
                blocked.append(r.request.url)
                r.abort()

        for view, (width, height) in VIEWPORTS.items():
            context = browser.new_context(viewport={"width": width, "height": height},
                                          offline=False)
            context.route("**/*", route)
            page = context.new_page()
            for path in pages:
                url = root + path.removesuffix("index.html")
                page.goto(url, wait_until="load")
                result = page.evaluate(PAGE_CHECK, [RAW_TEX, PROGRESS,
                                                    path.startswith("notebooks/")])
                problems += [f"{view} {path}: {x}" for x in result["problems"]]
                if view == "desktop":
                    totals["pages"] += 1
                    totals["formulas"] += result["maths"]
                    totals["blocks"] += result["blocks"]
                totals["wide blocks that scroll"] += result["wide"]
                if screenshots and view == "desktop" and result["maths"]:
                    screenshots.mkdir(parents=True, exist_ok=True)
                    for i, formula in enumerate(page.locator("article math").all()):
                        name = path.replace("/index.html", "").replace("/", "-")
                        block = formula.get_attribute("display") == "block"
                        (formula if block else formula.locator("xpath=..")).screenshot(
                            path=screenshots / f"formula-{name}-{i}.png")
                if screenshots and path in ("index.html", "cli-reference/index.html",
                                            "exact/index.html", "tasks/index.html",
                                            "notebooks/02_bifurcation_sweep/index.html"):
                    screenshots.mkdir(parents=True, exist_ok=True)
                    name = path.replace("/index.html", "").replace("index.html", "home")
                    page.screenshot(path=screenshots / f"{view}-{name.replace('/', '-')}.png")
            context.close()

        # the task index, reached from the home page by its link
        context = browser.new_context(viewport={"width": 1280, "height": 900})
        context.route("**/*", route)
        page = context.new_page()
        page.goto(root, wait_until="load")
        in_nav = page.locator("nav.md-nav--primary a[href='tasks/']").count()
        print(f"task index: {in_nav} link(s) to it in the home page's navigation")
        if in_nav == 0:
            problems.append("home page: no link to the task index in the navigation")
        link = page.locator("article a[href*='tasks/']").first
        if link.count() == 0:
            problems.append("home page: no link to the task index")
        else:
            link.click()
            page.wait_for_load_state("load")
            title = page.locator("article h1").first.inner_text()
            if not page.url.rstrip("/").endswith("tasks") or not title.startswith("How do I"):
                problems.append(f"home page's link led to {page.url} ({title!r})")
            else:
                print(f"task index: reached from the home page by its link: {page.url} "
                      f"({title!r}, {page.locator('article h2').count()} tasks)")
        context.close()
        browser.close()
    server.shutdown()

    for problem in problems:
        print("PROBLEM", problem)
    for url in sorted(set(blocked)):
        print("BLOCKED (a request to another host)", url)
    print(", ".join(f"{v} {k}" for k, v in totals.items())
          + f" ({len(VIEWPORTS)} window widths: "
          + ", ".join(f"{k} {w}px" for k, (w, _) in VIEWPORTS.items()) + ")")
    print(f"{len(problems)} problems, {len(set(blocked))} requests to other hosts")
    return 1 if problems or blocked else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("site", type=Path, help="the built site (mkdocs build --site-dir)")
    parser.add_argument("--chromium", help="path of a Chromium to launch")
    parser.add_argument("--screenshots", type=Path, help="a folder for a few screenshots")
    args = parser.parse_args()
    if not (args.site / "index.html").is_file():
        parser.exit(2, f"{args.site}: no index.html (build the site first)\n")
    return check(args.site, chromium_path(args.chromium), args.screenshots)


if __name__ == "__main__":
    sys.exit(main())
