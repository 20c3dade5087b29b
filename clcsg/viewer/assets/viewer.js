// clcsg view: the page's side.  It keeps the orbit view (target, distance, azimuth, elevation,
// fov; z up), turns mouse, wheel and touch input into it, asks the server for frames over the
// websocket (half size as JPEG while the view moves, full size as PNG once it rests) and
// draws the newest frame it gets.  window.clcsgViewer exposes the state (tests read it).
"use strict";

(function () {
  const token = document.querySelector('meta[name="clcsg-token"]').content;
  const canvas = document.getElementById("view");
  const ctx2d = canvas.getContext("2d");
  const errorBox = document.getElementById("error");
  const statusLine = document.getElementById("status");
  const radiusInput = document.getElementById("radius");
  const exact = document.getElementById("exact");

  const REST_DELAY_MS = 150;   // the view rests this long after the last input
  const ORBIT_DEG_PER_PX = 0.4;
  const state = {
    view: null, connected: false, frames: 0, last: null, model: null, error: null,
    nextId: 0, shownId: -1, sent: new Map(), restTimer: null, dragQueued: false, busy: "",
  };
  window.clcsgViewer = state;

  // -- the websocket ---------------------------------------------------------------------------
  const ws = new WebSocket(`ws://${location.host}/ws?token=${encodeURIComponent(token)}`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.connected = true;
    resize();
    send({ type: "hello", width: canvas.width, height: canvas.height });
  };
  ws.onclose = () => {
    state.connected = false;
    showError("disconnected: the clcsg view server has stopped");
    statusLine.textContent = "disconnected";
  };
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") onText(JSON.parse(ev.data));
    else onFrame(ev.data);
  };

  function send(msg) {
    if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg));
  }

  function onText(msg) {
    if (msg.type === "scene") {
      state.model = msg.model;
      state.busy = "";
      if (msg.model) radiusInput.value = msg.model.auto_radius ? "auto" : formatNumber(msg.model.radius);
      showError(msg.error ? `${msg.error}\n(showing the last good model)` : null);
      if (state.view) requestFrame("rest");
      updateStatus();
    } else if (msg.type === "view") {
      state.view = msg.view;
      requestFrame("rest");
    } else if (msg.type === "error") {
      state.busy = "";
      showError(msg.frame === undefined ? `${msg.message}\n(showing the last good model)` : msg.message);
      updateStatus();
    }
  }

  function onFrame(buffer) {
    const n = new DataView(buffer).getUint32(0, true);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
    if (header.id < state.shownId) return;  // an older camera: a newer frame is on screen
    const blob = new Blob([new Uint8Array(buffer, 4 + n)], { type: `image/${header.format}` });
    createImageBitmap(blob).then((bitmap) => {
      if (header.id < state.shownId) return;
      state.shownId = header.id;
      ctx2d.imageSmoothingEnabled = true;
      ctx2d.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
      bitmap.close();
      const sentAt = state.sent.get(header.id);
      header.roundtrip_ms = sentAt === undefined ? null : performance.now() - sentAt;
      for (const id of state.sent.keys()) if (id < header.id) state.sent.delete(id);
      state.last = header;
      state.frames += 1;
      if (header.method === "raytrace" || header.quality === "rest") state.busy = "";
      updateStatus();
    });
  }

  // -- frames ----------------------------------------------------------------------------------
  function requestFrame(quality) {
    if (!state.view) return;
    const full = quality === "rest";
    const id = state.nextId++;
    const width = full ? canvas.width : Math.max(1, Math.round(canvas.width / 2));
    const height = full ? canvas.height : Math.max(1, Math.round(canvas.height / 2));
    const method = full && exact.checked ? "raytrace" : "splat";
    if (method === "raytrace") state.busy = "ray tracing...";
    state.sent.set(id, performance.now());
    send({ type: "frame", id, view: state.view, width, height, quality, method });
  }

  function moved() {  // the view changed: a small frame now (once per animation frame), a full one at rest
    if (!state.dragQueued) {
      state.dragQueued = true;
      requestAnimationFrame(() => { state.dragQueued = false; requestFrame("drag"); });
    }
    clearTimeout(state.restTimer);
    state.restTimer = setTimeout(() => { if (!pointers.size) requestFrame("rest"); }, REST_DELAY_MS);
  }

  // -- the orbit view ----------------------------------------------------------------------------
  function frameVectors(v) {
    const az = v.azimuth * Math.PI / 180, el = v.elevation * Math.PI / 180;
    const back = [Math.cos(el) * Math.cos(az), Math.cos(el) * Math.sin(az), Math.sin(el)];
    const right = [-Math.sin(az), Math.cos(az), 0];  // forward x z, normalized
    const up = [-back[2] * right[1], back[2] * right[0], back[0] * right[1] - back[1] * right[0]];
    return { right, up };
  }

  function orbit(dx, dy) {
    const v = state.view;
    v.azimuth = (v.azimuth - dx * ORBIT_DEG_PER_PX) % 360;
    v.elevation = Math.max(-89, Math.min(89, v.elevation + dy * ORBIT_DEG_PER_PX));
  }

  function pan(dx, dy) {
    const v = state.view;
    const perPx = 2 * v.distance * Math.tan(v.fov * Math.PI / 360) / Math.max(1, canvas.height);
    const { right, up } = frameVectors(v);
    for (let k = 0; k < 3; k++) v.target[k] += (-dx * right[k] + dy * up[k]) * perPx;
  }

  function zoom(factor) {
    state.view.distance = Math.max(1e-9, state.view.distance * factor);
  }

  // -- input: mouse, wheel, touch (pointer events) -----------------------------------------------
  const pointers = new Map();
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey });
    canvas.classList.add("dragging");
    e.preventDefault();
  });
  canvas.addEventListener("pointermove", (e) => {
    const p = pointers.get(e.pointerId);
    if (!p || !state.view) return;
    const dx = e.clientX - p.x, dy = e.clientY - p.y;
    if (pointers.size === 1) {
      if (p.pan) pan(dx, dy); else orbit(dx, dy);
    } else if (pointers.size === 2) {  // pinch: zoom by the change of spread, pan by the midpoint
      const other = [...pointers.entries()].find(([id]) => id !== e.pointerId)[1];
      const before = Math.hypot(p.x - other.x, p.y - other.y);
      const after = Math.hypot(e.clientX - other.x, e.clientY - other.y);
      if (before > 0 && after > 0) zoom(before / after);
      pan(dx / 2, dy / 2);
    }
    p.x = e.clientX;
    p.y = e.clientY;
    moved();
  });
  function release(e) {
    if (!pointers.delete(e.pointerId)) return;
    if (!pointers.size) {
      canvas.classList.remove("dragging");
      clearTimeout(state.restTimer);
      requestFrame("rest");
    }
  }
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("wheel", (e) => {
    if (!state.view) return;
    e.preventDefault();
    const scale = e.deltaMode === 1 ? 40 : e.deltaMode === 2 ? 800 : 1;
    zoom(Math.exp(e.deltaY * scale * 0.0015));
    moved();
  }, { passive: false });

  // -- controls ----------------------------------------------------------------------------------
  document.getElementById("fit").onclick = () => send({ type: "fit", width: canvas.width, height: canvas.height });
  exact.onchange = () => requestFrame("rest");
  function applyRadius() {
    state.busy = "sampling...";
    updateStatus();
    send({ type: "radius", value: radiusInput.value.trim() || "auto" });
  }
  document.getElementById("apply-radius").onclick = applyRadius;
  radiusInput.addEventListener("keydown", (e) => { if (e.key === "Enter") applyRadius(); });

  function download(name, extra) {
    if (!state.view) return;
    const q = new URLSearchParams({ token, view: JSON.stringify(state.view), width: canvas.width,
                                    height: canvas.height, method: exact.checked ? "raytrace" : "splat", ...extra });
    const a = document.createElement("a");
    a.href = `/save/${name}?${q}`;
    a.download = "";
    document.body.appendChild(a);
    a.click();
    a.remove();
  }
  document.getElementById("save-png").onclick = () => download("view.png", { aa: 3 });
  document.getElementById("save-npz").onclick = () => download("view.npz", { aa: 3 });
  document.getElementById("save-ply").onclick = () => download("samples.ply", {});

  // -- layout and status -------------------------------------------------------------------------
  function resize() {
    const r = canvas.getBoundingClientRect();
    const w = Math.max(1, Math.round(r.width)), h = Math.max(1, Math.round(r.height));
    if (w === canvas.width && h === canvas.height) return false;
    canvas.width = w;
    canvas.height = h;
    return true;
  }
  new ResizeObserver(() => { if (resize()) moved(); }).observe(document.getElementById("stage"));

  function showError(text) {
    state.error = text;
    errorBox.textContent = text || "";
    errorBox.style.display = text ? "block" : "none";
  }

  function formatNumber(x) {
    return Number(x).toPrecision(4).replace(/\.?0+(e|$)/, "$1");
  }

  function updateStatus() {
    const m = state.model, f = state.last, parts = [];
    if (m) {
      parts.push(`${m.samples.toLocaleString("en-US")} samples`, `r = ${formatNumber(m.radius)}${m.auto_radius ? " (auto)" : ""}`,
                 `${m.quadrics} quadrics`, `sampling ${(m.sample_s ?? 0).toFixed(2)} s`);
    }
    if (f) {
      const wait = f.roundtrip_ms === null ? "" : ` + ${Math.max(0, f.roundtrip_ms - f.render_ms - f.encode_ms).toFixed(0)} wait/transfer`;
      const reduced = f.reduced ? " (smaller: the ray tracer's time budget)" : "";
      parts.push(`frame ${f.width}x${f.height}${reduced} ${f.method}${f.aa > 1 ? ` ${f.aa}x${f.aa} aa` : ""}: ` +
                 `${f.render_ms.toFixed(0)} ms render + ${f.encode_ms.toFixed(0)} ${f.format}${wait}`);
    }
    if (state.busy) parts.push(state.busy);
    statusLine.textContent = parts.join(" \u00b7 ") || "waiting for the first frame...";
  }
})();
