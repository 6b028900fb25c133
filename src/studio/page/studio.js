// The studio page: a gallery, a 3D view of any level of any shape beside
// the exemplar (one camera), and the steering controls. Everything it needs
// comes from the studio's own server (three.js is vendored).
import * as THREE from 'three';
import { OrbitControls } from '/assets/OrbitControls.js';
import { PLYLoader } from '/assets/PLYLoader.js';

const $ = (id) => document.getElementById(id);
// The token stays out of the address bar (and the history, and a shared
// screenshot): the studio's cookie, which no script can read, carries it.
if (new URLSearchParams(location.search).has('token')) history.replaceState(null, '', location.pathname);

// ---- server calls ----------------------------------------------------------
async function call(method, path, body) {
  const r = await fetch(path, {
    method,
    headers: body ? { 'Content-Type': 'application/json' } : {},
    body: body ? JSON.stringify(body) : undefined,
  });
  if (!r.ok) {
    let msg = `${r.status}`;
    try { msg = (await r.json()).error || msg; } catch (_) { /* not JSON */ }
    throw new Error(msg);
  }
  return r;
}
const getJson = async (path) => (await call('GET', path)).json();
const postJson = async (path, body) => (await call('POST', path, body || {})).json();

function say(text, error = false) {
  const m = $('message');
  m.textContent = text;
  m.className = error ? 'error' : '';
}
async function attempt(what, f) {
  try { return await f(); } catch (e) { say(`${what}: ${e.message}`, true); return undefined; }
}

// ---- state -----------------------------------------------------------------
const S = {
  state: null,      // the server's /api/state
  selected: 'exemplar',
  level: null,      // level index shown
  follow: true,     // show each new level of the selected shape as it arrives
  draft: null,      // the draft under edit (summary)
  box: null,        // {min:[..], max:[..]} in voxels of the shown level
  loaded: {},       // key -> {n, resolution, coords, ...}
  askedAt: null,    // performance.now() of the last regenerate / sample click
  timings: [],      // [{shape, level, resolution, ms}] edit -> level on screen
};
window.studio = S; // for the browser test

// ---- 3D view ---------------------------------------------------------------
const canvas = $('canvas');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
renderer.setClearColor(0x2a2c32);
const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = false;
const left = new THREE.Scene();
const right = new THREE.Scene();
for (const s of [left, right]) {
  s.add(new THREE.HemisphereLight(0xffffff, 0x444444, 1.2));
  const d = new THREE.DirectionalLight(0xffffff, 1.5);
  d.position.set(1, 2, 1.5);
  s.add(d);
}
let leftPoints = null, rightPoints = null, leftMesh = null, boxHelper = null;

const pointMaterial = () => new THREE.ShaderMaterial({
  vertexColors: true,
  uniforms: { size: { value: 0.02 }, scale: { value: 400 } },
  vertexShader: `
    uniform float size; uniform float scale;
    varying vec3 vColor;
    void main() {
      vec4 mv = modelViewMatrix * vec4(position, 1.0);
      vec3 n = normalize(normalMatrix * normal);
      float lit = 0.35 + 0.65 * abs(dot(n, normalize(vec3(0.35, 0.75, 0.55))));
      vColor = color * lit;
      gl_PointSize = max(1.5, size * scale / -mv.z);
      gl_Position = projectionMatrix * mv;
    }`,
  fragmentShader: `
    varying vec3 vColor;
    void main() {
      vec2 d = gl_PointCoord - 0.5;
      if (dot(d, d) > 0.25) discard;
      gl_FragColor = vec4(vColor, 1.0);
    }`,
});

function parsePoints(buf) {
  const h = new Uint32Array(buf, 0, 4);
  if (h[0] !== 0x31505353) throw new Error('not a points payload'); // "SSP1"
  const n = h[1];
  return {
    n, resolution: h[2], index: h[3],
    positions: new Float32Array(buf, 16, 3 * n),
    coords: new Int16Array(buf, 16 + 12 * n, 3 * n),
    normals: new Int8Array(buf, 16 + 18 * n, 3 * n),
    colours: new Uint8Array(buf, 16 + 21 * n, 3 * n),
  };
}

function pointsObject(p) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(p.positions, 3));
  g.setAttribute('normal', new THREE.BufferAttribute(p.normals, 3, true));
  g.setAttribute('color', new THREE.BufferAttribute(p.colours, 3, true));
  const m = pointMaterial();
  m.uniforms.size.value = (2 / p.resolution) * parseFloat($('point-size').value);
  const o = new THREE.Points(g, m);
  o.userData.payload = p;
  return o;
}

// The exemplar's levels never change: fetched once each.
const exemplarPoints = {};
async function loadPoints(id, k) {
  if (id === 'exemplar' && exemplarPoints[k]) return exemplarPoints[k];
  const buf = await (await call('GET', `/api/shapes/${id}/levels/${k}/points`)).arrayBuffer();
  const p = parsePoints(buf);
  if (id === 'exemplar') exemplarPoints[k] = p;
  return p;
}

function setObject(scene, old, obj) {
  if (old) { scene.remove(old); old.geometry.dispose(); old.material.dispose(); }
  if (obj) scene.add(obj);
  return obj;
}

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
  }
  camera.aspect = (w / 2) / Math.max(h, 1);
  camera.updateProjectionMatrix();
}

function render() {
  resize();
  const w = canvas.clientWidth, h = canvas.clientHeight;
  const scale = h * camera.projectionMatrix.elements[5] / 2;
  for (const o of [leftPoints, rightPoints]) if (o) o.material.uniforms.scale.value = scale;
  renderer.setScissorTest(true);
  renderer.setViewport(0, 0, w / 2, h); renderer.setScissor(0, 0, w / 2, h);
  renderer.render(left, camera);
  renderer.setViewport(w / 2, 0, w / 2, h); renderer.setScissor(w / 2, 0, w / 2, h);
  renderer.render(right, camera);
}
controls.addEventListener('change', render);
window.addEventListener('resize', render);

function resetCamera() {
  const up = S.state && S.state.up === 'z' ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(0, 1, 0);
  camera.up.copy(up);
  const dir = up.z ? new THREE.Vector3(1.6, -2.2, 1.3) : new THREE.Vector3(1.6, 1.3, 2.2);
  camera.position.copy(dir.normalize().multiplyScalar(4.2));
  controls.target.set(0, 0, 0);
  controls.update();
  render();
}

function voxelBounds(b, res) {
  const s = 2 / res;
  return new THREE.Box3(
    new THREE.Vector3(-1 + b.min[0] * s, -1 + b.min[1] * s, -1 + b.min[2] * s),
    new THREE.Vector3(-1 + (b.max[0] + 1) * s, -1 + (b.max[1] + 1) * s, -1 + (b.max[2] + 1) * s));
}

function drawBox() {
  if (boxHelper) { left.remove(boxHelper); boxHelper = null; }
  const p = leftPoints && leftPoints.userData.payload;
  if (S.box && S.draft && S.selected === S.draft.id && p) {
    boxHelper = new THREE.Box3Helper(voxelBounds(S.box, p.resolution), 0xe89a3c);
    left.add(boxHelper);
  }
  render();
}

// Shows level k of shape id on the left and the exemplar's level k on the right.
async function show(id, k, why) {
  S.selected = id; S.level = k;
  const [p, e] = await Promise.all([loadPoints(id, k), loadPoints('exemplar', Math.min(k, S.state.resolutions.length - 1))]);
  if (S.selected !== id || S.level !== k) return; // a later click won
  leftPoints = setObject(left, leftPoints, pointsObject(p));
  if (!rightPoints || rightPoints.userData.payload !== e) rightPoints = setObject(right, rightPoints, pointsObject(e));
  await updateMesh();
  $('left-label').textContent = `${id} level ${k} (${p.resolution}^3, ${p.n} points)`;
  drawBox();
  if (why && S.askedAt !== null) {
    const ms = performance.now() - S.askedAt;
    S.timings.push({ shape: id, level: k, resolution: p.resolution, ms });
    $('timing').textContent = `${why}: level ${k} (${p.resolution}^3) on screen ${(ms / 1000).toFixed(2)} s after the click`;
  }
  renderLevels(); renderShapeInfo();
}

async function updateMesh() {
  if (leftMesh) { left.remove(leftMesh); leftMesh.geometry.dispose(); leftMesh = null; }
  const shape = shapeOf(S.selected);
  const want = $('show-mesh').checked && shape && shape.has_mesh;
  $('mesh-toggle').hidden = !(shape && shape.has_mesh);
  if (!want) { if (leftPoints) leftPoints.visible = true; return; }
  const buf = await (await call('GET', `/api/shapes/${S.selected}/mesh.ply`)).arrayBuffer();
  const g = new PLYLoader().parse(buf);
  g.computeVertexNormals();
  const m = new THREE.Mesh(g, new THREE.MeshStandardMaterial({ vertexColors: g.hasAttribute('color'), roughness: 0.9 }));
  const c = S.state.frame_centre, s = S.state.frame_scale;
  m.scale.setScalar(s);
  m.position.set(-c[0] * s, -c[1] * s, -c[2] * s);
  leftMesh = m; left.add(m);
  if (leftPoints) leftPoints.visible = false;
  render();
}

// ---- box select with the mouse (shift+drag on the left view) ---------------
let drag = null;
canvas.addEventListener('pointerdown', (ev) => {
  if (!ev.shiftKey || !S.draft || !leftPoints) return;
  const r = canvas.getBoundingClientRect();
  if (ev.clientX - r.left > r.width / 2) return;
  controls.enabled = false;
  drag = { x0: ev.clientX - r.left, y0: ev.clientY - r.top, x1: ev.clientX - r.left, y1: ev.clientY - r.top };
  canvas.setPointerCapture(ev.pointerId);
});
canvas.addEventListener('pointermove', (ev) => {
  if (!drag) return;
  const r = canvas.getBoundingClientRect();
  drag.x1 = ev.clientX - r.left; drag.y1 = ev.clientY - r.top;
  const el = $('select-rect');
  el.hidden = false;
  el.style.left = `${Math.min(drag.x0, drag.x1)}px`; el.style.top = `${Math.min(drag.y0, drag.y1)}px`;
  el.style.width = `${Math.abs(drag.x1 - drag.x0)}px`; el.style.height = `${Math.abs(drag.y1 - drag.y0)}px`;
});
canvas.addEventListener('pointerup', () => {
  if (!drag) return;
  $('select-rect').hidden = true;
  controls.enabled = true;
  const d = drag; drag = null;
  selectRect(d);
});

// Every voxel whose point projects inside the rectangle (through the whole
// depth) joins the box.
function selectRect(d) {
  const p = leftPoints.userData.payload;
  const w = canvas.clientWidth / 2, h = canvas.clientHeight;
  const [x0, x1] = [Math.min(d.x0, d.x1), Math.max(d.x0, d.x1)];
  const [y0, y1] = [Math.min(d.y0, d.y1), Math.max(d.y0, d.y1)];
  const v = new THREE.Vector3();
  let min = null, max = null;
  for (let i = 0; i < p.n; i++) {
    v.set(p.positions[3 * i], p.positions[3 * i + 1], p.positions[3 * i + 2]).project(camera);
    const sx = (v.x + 1) / 2 * w, sy = (1 - v.y) / 2 * h;
    if (sx < x0 || sx > x1 || sy < y0 || sy > y1 || v.z > 1) continue;
    const c = [p.coords[3 * i], p.coords[3 * i + 1], p.coords[3 * i + 2]];
    min = min ? min.map((m, a) => Math.min(m, c[a])) : c.slice();
    max = max ? max.map((m, a) => Math.max(m, c[a])) : c.slice();
  }
  if (!min) { say('no voxel inside the rectangle'); return; }
  setBox({ min, max });
  say(`box ${min.join(',')} .. ${max.join(',')}`);
}

function setBox(b) {
  S.box = b;
  ['x', 'y', 'z'].forEach((a, i) => { $(`b${a}0`).value = b.min[i]; $(`b${a}1`).value = b.max[i]; });
  drawBox();
}
function boxFromFields() {
  const get = (id) => parseInt($(id).value, 10);
  const b = { min: [get('bx0'), get('by0'), get('bz0')], max: [get('bx1'), get('by1'), get('bz1')] };
  if ([...b.min, ...b.max].some(Number.isNaN)) return null;
  return b;
}
for (const id of ['bx0', 'by0', 'bz0', 'bx1', 'by1', 'bz1']) $(id).addEventListener('change', () => { const b = boxFromFields(); if (b) setBox(b); });

// ---- editing ---------------------------------------------------------------
async function edit(body) {
  if (!S.draft) { say('start an edit first', true); return; }
  const r = await attempt('edit', () => postJson(`/api/drafts/${S.draft.id}/edit`, body));
  if (!r) return;
  S.draft = r.draft;
  say(r.did);
  renderDraft();
  await show(S.draft.id, S.draft.level);
}
const needBox = () => { const b = boxFromFields(); if (!b) say('select a box first (shift+drag, or type its corners)', true); return b; };
// The mirror plane (off, x or z) goes with every delete and move.
const mirrored = (e) => ($('mirror').value ? { ...e, mirror: $('mirror').value } : e);
$('op-delete').onclick = () => { const b = needBox(); if (b) edit(mirrored({ op: 'delete', box: b })); };
$('op-copy').onclick = () => { const b = needBox(); if (b) edit({ op: 'copy', box: b }); };
$('op-copy-exemplar').onclick = () => { const b = needBox(); if (b) edit({ op: 'copy_exemplar', box: b }); };
$('op-paste').onclick = () => { const b = needBox(); if (b) edit({ op: 'paste', to: b.min }); };
$('op-move').onclick = () => {
  const b = needBox(); if (!b) return;
  const by = ['mx', 'my', 'mz'].map((id) => parseInt($(id).value, 10) || 0);
  moveVoxels(b, by);
};
async function moveVoxels(b, by) {
  await edit(mirrored({ op: 'move', box: b, by }));
  setBox({ min: b.min.map((m, i) => m + by[i]), max: b.max.map((m, i) => m + by[i]) });
}
$('op-undo').onclick = () => edit({ op: 'undo' });
$('op-redo').onclick = () => edit({ op: 'redo' });

$('start-edit').onclick = async () => {
  const k = parseInt($('edit-level').value, 10);
  const source = S.selected.startsWith('d') && S.draft ? S.draft.source : S.selected;
  const d = await attempt('edit', () => postJson('/api/drafts', { source, level: k }));
  if (!d) return;
  S.draft = d;
  $('editor').hidden = false;
  renderDraft();
  say(`editing ${source} level ${k}: shift+drag to select`);
  await show(d.id, k);
};
$('discard-draft').onclick = async () => {
  if (!S.draft) return;
  await attempt('discard', () => postJson(`/api/drafts/${S.draft.id}/discard`));
  const source = S.draft.source;
  S.draft = null; S.box = null;
  $('editor').hidden = true;
  await selectShape(source);
};
$('regenerate').onclick = () => regenerate();
async function regenerate() {
  if (!S.draft) return;
  S.askedAt = performance.now(); S.follow = true;
  const j = await attempt('regenerate', () => postJson('/api/jobs', { kind: 'regenerate', draft: S.draft.id }));
  if (j) { S.followJob = j.id; say(`regenerating (job ${j.id})`); poll(); }
}

function renderDraft() {
  const d = S.draft;
  if (!d) return;
  $('draft-info').textContent = `${d.id}: ${d.source} level ${d.level} (${d.resolution}^3), ${d.voxels} voxels; ${d.edits.length} edit(s)` +
    (d.edits.length ? `: ${d.edits[d.edits.length - 1]}` : '');
  $('op-undo').disabled = !d.can_undo;
  $('op-redo').disabled = !d.can_redo;
}

document.addEventListener('keydown', (ev) => {
  if (!S.draft || ['INPUT', 'SELECT', 'TEXTAREA'].includes(document.activeElement.tagName)) return;
  const b = boxFromFields();
  const step = { ArrowLeft: [-1, 0, 0], ArrowRight: [1, 0, 0], ArrowUp: [0, 0, -1], ArrowDown: [0, 0, 1], PageUp: [0, 1, 0], PageDown: [0, -1, 0] }[ev.key];
  if (step && b) {
    ev.preventDefault();
    const by = S.state.up === 'z' ? [step[0], -step[2], step[1]] : step;
    if (ev.shiftKey) moveVoxels(b, by);
    else setBox({ min: b.min.map((m, i) => m + by[i]), max: b.max.map((m, i) => m + by[i]) });
  } else if ((ev.key === 'Delete' || ev.key === 'Backspace') && b) { ev.preventDefault(); edit(mirrored({ op: 'delete', box: b })); }
  else if (ev.ctrlKey && ev.key === 'c' && b) { ev.preventDefault(); edit({ op: 'copy', box: b }); }
  else if (ev.ctrlKey && ev.key === 'v' && b) { ev.preventDefault(); edit({ op: 'paste', to: b.min }); }
  else if (ev.ctrlKey && (ev.key === 'y' || (ev.key === 'Z' && ev.shiftKey) || (ev.key === 'z' && ev.shiftKey))) { ev.preventDefault(); edit({ op: 'redo' }); }
  else if (ev.ctrlKey && ev.key === 'z') { ev.preventDefault(); edit({ op: 'undo' }); }
  else if (ev.key === 'Enter') { ev.preventDefault(); regenerate(); }
});

// ---- jobs ------------------------------------------------------------------
for (const a of ['ex', 'ey', 'ez']) $(a).addEventListener('input', () => { $(`${a}-out`).textContent = $(a).value; });
$('sample').onclick = async () => {
  const n = parseInt($('n').value, 10);
  const seed = $('seed').value === '' ? null : parseInt($('seed').value, 10);
  const extent = ['ex', 'ey', 'ez'].map((a) => parseFloat($(a).value));
  S.askedAt = performance.now(); S.follow = true;
  const j = await attempt('sample', () => postJson('/api/jobs', { kind: 'sample', n, seed, extent }));
  if (j) { S.followJob = j.id; say(`sampling ${n} new variant(s) (job ${j.id})`); poll(); }
};
$('more-like').onclick = async () => {
  const source = S.selected;
  const keep_level = parseInt($('keep-level').value, 10);
  const n = parseInt($('more-n').value, 10);
  S.askedAt = performance.now(); S.follow = true;
  const j = await attempt('more like this', () => postJson('/api/jobs', { kind: 'more_like', source, keep_level, n, seed: null }));
  if (j) { S.followJob = j.id; say(`${n} more like ${source} (job ${j.id})`); poll(); }
};
$('keep').onclick = async () => {
  const j = await attempt('keep', () => postJson('/api/jobs', { kind: 'keep', shape: S.selected }));
  if (j) { say(`keeping ${S.selected} (job ${j.id}): writing its level files, mesh, USD and evaluation`); poll(); }
};
$('discard').onclick = async () => {
  const id = S.selected;
  const r = await attempt('discard', () => postJson(`/api/shapes/${id}/discard`));
  if (r) { say(`${id} discarded`); await refresh(); await selectShape('exemplar'); }
};
async function cancelJob(id) { await attempt('cancel', () => postJson(`/api/jobs/${id}/cancel`)); poll(); }

// ---- the gallery and the rest ------------------------------------------------
const shapeOf = (id) => S.state && S.state.shapes.find((s) => s.id === id);
// Every string that comes from a run folder or the server goes into markup
// through this: a flag or name in a shared run's eval.json is text, never
// markup or script.
const esc = (x) => String(x).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));

function flagsHtml(s) {
  const v = s.verdict;
  if (s.id === 'exemplar') return '<span class="flag info">exemplar</span>';
  if (!v) return s.levels.length ? '<span class="flag info">judging…</span>' : '<span class="flag info">in progress</span>';
  if (v.by.startsWith('not judged')) return '<span class="flag info">not judged</span>';
  const out = [];
  out.push(v.whole ? '<span class="flag whole">whole</span>' : '<span class="flag">broken</span>');
  if (v.near_copy) out.push('<span class="flag copy">near copy</span>');
  for (const f of v.flags) if (f !== 'near_copy') out.push(`<span class="flag">${esc(f)}</span>`);
  return out.join('');
}

function renderGallery() {
  const g = $('gallery');
  const cards = [];
  for (const s of S.state.shapes) {
    const origin = s.origin.kind === 'session' ? s.origin.made_by : s.origin.kind === 'run' ? 'run variant' : 'the encoded exemplar';
    const finished = s.verdict || s.origin.kind !== 'session';
    const key = `${s.id}:${s.levels.join(',')}:${finished}`;
    const img = finished && s.levels.length ? `<img alt="${esc(s.id)}" src="/api/shapes/${encodeURIComponent(s.id)}/preview.png?v=${encodeURIComponent(key)}">` : '';
    cards.push(`<div class="card${s.id === S.selected || (S.draft && S.selected === S.draft.id && s.id === S.draft.source) ? ' selected' : ''}" data-id="${esc(s.id)}">
      ${img}<div class="name">${esc(s.id)}${s.kept_as ? ` → ${esc(s.kept_as)}` : ''}</div>
      <div class="origin">${esc(origin)}</div><div>${flagsHtml(s)}</div></div>`);
  }
  const html = cards.join('');
  if (g.dataset.html !== html) {
    g.innerHTML = html; g.dataset.html = html;
    for (const c of g.querySelectorAll('.card')) c.onclick = () => selectShape(c.dataset.id);
  }
}

function renderJobs() {
  const el = $('jobs');
  const shown = S.state.jobs.slice(-6);
  el.innerHTML = shown.map((j) => `<div class="job ${esc(j.state)}" data-id="${esc(j.id)}" title="${esc(j.message)}">
    ${esc(j.id)} ${esc(j.kind)} <progress max="1" value="${Number(j.progress)}"></progress> ${esc(j.state)}${j.state === 'done' ? ` ${Number(j.seconds).toFixed(1)} s` : ''}
    ${j.state === 'queued' || j.state === 'running' ? `<button data-cancel="${esc(j.id)}">cancel</button>` : ''}</div>`).join('');
  for (const b of el.querySelectorAll('button[data-cancel]')) b.onclick = () => cancelJob(b.dataset.cancel);
}

function renderLevels() {
  const s = shapeOf(S.selected);
  const el = $('levels');
  if (S.draft && S.selected === S.draft.id) {
    el.innerHTML = `<button class="on">edit of level ${esc(S.draft.level)}</button>`;
    $('view-title').textContent = `${S.draft.id} (editing ${S.draft.source})`;
    return;
  }
  if (!s) { el.innerHTML = ''; return; }
  el.innerHTML = s.levels.map((k) => `<button data-k="${esc(k)}" class="${k === S.level ? 'on' : ''}">${esc(S.state.resolutions[k])}³</button>`).join('');
  for (const b of el.querySelectorAll('button')) b.onclick = () => { S.follow = false; show(S.selected, parseInt(b.dataset.k, 10)); };
  $('view-title').textContent = s.id;
}

function renderShapeInfo() {
  const s = shapeOf(S.selected);
  const session = s && s.origin.kind === 'session';
  $('keep').disabled = !(session && s.verdict && !s.kept_as);
  $('discard').disabled = !(session && !s.kept_as);
  $('more-like').disabled = !s || s.id === 'exemplar';
  $('start-edit').disabled = !s && !(S.draft && S.selected === S.draft.id);
  if (!s) { $('shape-info').textContent = ''; return; }
  const v = s.verdict;
  $('shape-info').textContent = `${s.id}: levels ${s.levels.join(', ')}` + (s.seed ? `; seed ${s.seed.seed}, index ${s.seed.index}` : '') +
    (v ? `; judged by ${v.by}: ${v.whole ? 'whole' : 'broken'}${v.near_copy ? ', a near copy' : ''}` : '') +
    (s.kept_as ? `; kept as ${s.kept_as}` : '');
}

function renderSelects() {
  const res = S.state.resolutions, last = res.length - 1;
  const opts = (max) => res.slice(0, max + 1).map((r, k) => `<option value="${k}">${k} (${esc(r)}³)</option>`).join('');
  if ($('keep-level').dataset.n !== String(last)) {
    $('keep-level').innerHTML = opts(last - 1); $('keep-level').value = '1';
    $('edit-level').innerHTML = opts(last - 1); $('edit-level').value = '1';
    $('keep-level').dataset.n = String(last);
  }
}

async function selectShape(id) {
  S.selected = id; S.follow = true;
  const s = shapeOf(id);
  renderGallery();
  if (s && s.levels.length) await show(id, s.levels[s.levels.length - 1]);
  else { renderLevels(); renderShapeInfo(); }
}

async function refresh() {
  S.state = await getJson('/api/state');
  $('run').textContent = `${S.state.exemplar} — ${S.state.run}`;
  const ready = $('ready');
  if (S.state.load_error) { ready.textContent = `networks not loaded: ${S.state.load_error}`; ready.className = 'pill bad'; }
  else if (S.state.ready) { ready.textContent = 'networks loaded'; ready.className = 'pill ok'; }
  renderSelects(); renderGallery(); renderJobs(); renderShapeInfo();
  $('clipboard').textContent = S.state.clipboard ? `clipboard: ${S.state.clipboard}` : 'clipboard: empty';
}

// While a job runs: follow its first output, each level shown as it is made.
let polling = false;
async function poll() {
  if (polling) return;
  polling = true;
  try {
    for (;;) {
      await refresh();
      const job = S.followJob && S.state.jobs.find((j) => j.id === S.followJob);
      if (job && job.outputs.length) {
        const out = shapeOf(job.outputs[0]);
        if (out && S.follow !== false) {
          const top = out.levels[out.levels.length - 1];
          if (S.selected !== out.id || S.level !== top) {
            if (S.selected !== out.id) S.level = null;
            S.follow = true;
            const why = job.kind === 'regenerate' ? 'edit' : job.kind.replace('_', ' ');
            await show(out.id, top, why);
          }
        }
      }
      const busy = S.state.jobs.some((j) => j.state === 'queued' || j.state === 'running') || !S.state.ready;
      if (!busy) { if (job) S.followJob = null; break; }
      await new Promise((r) => setTimeout(r, 100));
    }
  } catch (e) { say(`lost the studio: ${e.message}`, true); }
  polling = false;
  renderGallery(); renderShapeInfo();
}

$('point-size').addEventListener('input', () => {
  for (const o of [leftPoints, rightPoints]) if (o) o.material.uniforms.size.value = (2 / o.userData.payload.resolution) * parseFloat($('point-size').value);
  render();
});
$('show-mesh').addEventListener('change', () => attempt('mesh', updateMesh));
$('reset-camera').onclick = resetCamera;

(async () => {
  await attempt('load', refresh);
  resetCamera();
  await attempt('load', () => selectShape('exemplar'));
  poll();
  document.body.dataset.loaded = '1';
})();
