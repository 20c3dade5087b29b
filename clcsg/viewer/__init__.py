"""``clcsg view``: a local web page that shows a scene and redraws it when its file changes.

The data flow:

1. :mod:`.session` loads the scene file (for ``.scad`` through ``openscad``, which also lists
   the files the program includes and uses), compiles and samples it on the chosen device,
   and keeps the last good :class:`~clcsg.viewer.session.Model`;
2. :mod:`.watch` watches those files (watchfiles) and asks for a reload when one changes;
3. :mod:`.server` (aiohttp) serves the page (``assets/index.html``, ``assets/viewer.js``) on
   127.0.0.1, takes camera requests over a websocket and answers with frames that
   :mod:`.frames` renders (splats, or the exact ray tracer) and encodes (JPEG while dragging,
   PNG at rest, supersampled when the time allows); reload results and errors go to every page.

Needs the ``view`` extra: ``pip install 'clcsg[view]'`` (aiohttp, watchfiles).
"""
