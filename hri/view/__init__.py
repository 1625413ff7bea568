"""`hri view`: a live page of cameras, overlays and decisions.

core.py     the state model fed by samples (pure: no zenoh, no web server)
draw.py     the overlays drawn with OpenCV, for `--snapshot` (the page draws the same layers in JS)
player.py   a recording as a seekable sequence of samples (play / pause / slider)
server.py   the aiohttp + zenoh shell and the `hri view` command
static/     the page: plain HTML, JS and CSS served from the package (no build step, no CDN)
"""

# The page's frame budget: the state model's default and the command line's (here, so that neither imports the
# other: core.py stays free of the CLI, command.py free of OpenCV).
DEFAULT_MAX_FPS = 10.0  # frames per second per camera sent to the page
