"""The page of ``accelcal serve`` (one levelled view per tab; see :mod:`.serve`)."""

PAGE = r"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>accelcal view</title>
<style>
 body { margin: 0; background: #111; color: #eee; font: 14px sans-serif; overflow: hidden; }
 #stage { position: relative; display: inline-block; cursor: grab; user-select: none; }
 #view { display: block; max-width: 100vw; max-height: 100vh; }
 #overlay { position: absolute; left: 0; top: 0; pointer-events: none; }
 #hud { position: absolute; left: 8px; top: 6px; background: rgba(0,0,0,.55);
        padding: 4px 8px; border-radius: 4px; pointer-events: none; white-space: pre; }
 #msg { position: absolute; left: 8px; bottom: 6px; color: #f88; }
</style></head>
<body tabindex="0">
<div id="stage"><canvas id="view" width="1" height="1"></canvas><canvas id="overlay"></canvas>
<div id="hud">connecting...</div></div><div id="msg"></div>
<script>
"use strict";
const RESET = {az: 0, el: 0, fov: 60};
const picture = document.getElementById('view'), overlay = document.getElementById('overlay');
const hud = document.getElementById('hud'), msg = document.getElementById('msg');
const token = new URLSearchParams(location.search).get('token');
const wsUrl = (location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/ws'
  + (token ? '?token=' + encodeURIComponent(token) : '');
const ws = new WebSocket(wsUrl);
ws.binaryType = 'arraybuffer';
let pose = Object.assign({}, RESET), info = null, pending = null, times = [];
let drawn = 0, lastSend = 0, measured = true, busy = null, shownRow = null;
let hudAt = -1e9, hudTimer = null;
const latencies = [];  // ms from a pose sent to the first image of that pose drawn
const painter = picture.getContext('2d', {alpha: false});
window.accelcal = {pose: () => pose, info: () => info, drawn: () => drawn,
                   fps: () => fps(), state: () => ws.readyState, latencies: () => latencies};
function fps() {
  const now = performance.now();
  times = times.filter(t => t > now - 2000);
  return times.length > 1 ? (times.length - 1) * 1000 / (times[times.length - 1] - times[0]) : 0;
}
function send(change) {
  Object.assign(pose, change);
  pose.fov = Math.min(170, Math.max(0.5, pose.fov));
  pose.el = Math.min(90, Math.max(-90, pose.el));
  pose.az = ((pose.az + 180) % 360 + 360) % 360 - 180;
  if (ws.readyState === 1) {
    lastSend = performance.now(); measured = false; ws.send(JSON.stringify(pose));
  }
}
// the JPEG decoded off the page's thread (createImageBitmap: in Chromium 150 it cost the
// browser 1 ms a frame where WebCodecs' ImageDecoder cost 7, benchmarks/bench_serve_browser.py)
function decode(bytes) {
  return createImageBitmap(new Blob([bytes], {type: 'image/jpeg'}));
}
async function show(bytes, meta) {
  try {
    const frame = await decode(bytes);
    if (picture.width !== frame.width || picture.height !== frame.height) {
      picture.width = frame.width; picture.height = frame.height;
    }
    painter.drawImage(frame, 0, 0);
    frame.close();
    info = meta; drawn += 1; times.push(performance.now());
    if (!measured && meta && Math.abs(meta.az - pose.az) < 1e-6
        && Math.abs(meta.el - pose.el) < 1e-6 && Math.abs(meta.fov - pose.fov) < 1e-6) {
      latencies.push(performance.now() - lastSend); measured = true;
    }
    draw(false);
  } catch (e) {
    msg.textContent = 'cannot draw a frame: ' + e;
  } finally {  // acknowledged drawn or not: the stream goes on
    if (ws.readyState === 1) ws.send(JSON.stringify({ack: meta ? meta.sent : 0}));
  }
}
ws.onmessage = (event) => {
  if (typeof event.data === 'string') {
    const data = JSON.parse(event.data);
    if (data.refused) { msg.textContent = 'refused: ' + data.refused; return; }
    if (data.error) { msg.textContent = data.error; return; }
    pending = data; return;
  }
  const meta = pending; pending = null;
  // frames are drawn in order: the next one waits for this one's decode
  busy = (busy || Promise.resolve()).then(() => show(event.data, meta));
};
ws.onclose = (event) => {
  if (!msg.textContent) msg.textContent = 'closed (' + event.code + ') ' + (event.reason || '');
};
// the horizon line is redrawn when it moves or the page is resized, the HUD 5 times a second
function draw(resized) {
  if (!info) return;
  const w = picture.clientWidth, h = picture.clientHeight, s = w / info.width;
  const row = info.horizon_row === null ? null : (info.horizon_row + 0.5) * s;
  if (resized || overlay.width !== w || overlay.height !== h || row !== shownRow) {
    if (overlay.width !== w || overlay.height !== h) { overlay.width = w; overlay.height = h; }
    const c = overlay.getContext('2d');
    c.clearRect(0, 0, w, h);
    // horizon_row is null when the horizon is not in the view: no line
    if (row !== null && row >= 0 && row <= h) {
      c.strokeStyle = 'rgba(255,220,0,.9)'; c.setLineDash([12, 8]); c.lineWidth = 1.5;
      c.beginPath(); c.moveTo(0, row); c.lineTo(w, row); c.stroke();
    }
    shownRow = row;
  }
  const wait = 200 - (performance.now() - hudAt);
  if (resized || wait <= 0) writeHud();
  else if (hudTimer === null) hudTimer = setTimeout(writeHud, wait);  // the last one too
}
function writeHud() {
  if (hudTimer !== null) { clearTimeout(hudTimer); hudTimer = null; }
  hudAt = performance.now();
  hud.textContent = 'az ' + info.az.toFixed(1) + '\u00b0  el ' + info.el.toFixed(1)
    + '\u00b0  fov ' + info.fov.toFixed(1) + '\u00b0  ' + fps().toFixed(1) + ' fps  '
    + (100 * info.covered).toFixed(0) + '% seen';
}
let drag = null;
const stage = document.getElementById('stage');
stage.addEventListener('mousedown', (e) => {
  drag = {x: e.clientX, y: e.clientY}; e.preventDefault();
});
window.addEventListener('mouseup', () => { drag = null; });
window.addEventListener('mousemove', (e) => {
  if (!drag || !info) return;
  const w = picture.clientWidth || info.width;
  const f = (w / 2) / Math.tan(pose.fov * Math.PI / 360);   // px per radian at the centre
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag = {x: e.clientX, y: e.clientY};
  send({az: pose.az - dx / f * 180 / Math.PI, el: pose.el + dy / f * 180 / Math.PI});
});
stage.addEventListener('wheel', (e) => {
  e.preventDefault(); send({fov: pose.fov * Math.pow(1.1, Math.sign(e.deltaY))});
}, {passive: false});
window.addEventListener('keydown', (e) => {
  const step = pose.fov / 10;
  if (e.key === 'r' || e.key === 'Home') send(Object.assign({}, RESET));
  else if (e.key === 'ArrowLeft') send({az: pose.az - step});
  else if (e.key === 'ArrowRight') send({az: pose.az + step});
  else if (e.key === 'ArrowUp') send({el: pose.el + step});
  else if (e.key === 'ArrowDown') send({el: pose.el - step});
  else if (e.key === '+' || e.key === '=') send({fov: pose.fov / 1.1});
  else if (e.key === '-') send({fov: pose.fov * 1.1});
});
window.addEventListener('resize', () => draw(true));
</script></body></html>
"""
"""The whole page: image, horizon line, HUD (az/el/fov, fps, coverage), input handlers."""
