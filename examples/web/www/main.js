// The yarnify browser demo: controls, pointer input and the frame loop
// around the WebAssembly `App`. Tests read `window.yarnify`.
import init, { patterns, start } from './pkg/yarnify_web.js';

const canvas = document.getElementById('fabric');
const statusLine = document.getElementById('status');
// What tests and curious users can reach from the console.
const yarnify = { ready: false, error: null, errors: [], substepsPerSecond: 0, frameMs: 0 };
window.yarnify = yarnify;

// name, label, min, max, step, default: the names `App.set` takes.
const CONTROLS = {
  model: [
    ['stretch', 'stretch k<sub>s</sub>', 100, 3000, 10, 800],
    ['bend', 'bending k<sub>b</sub>', 0, 30, 0.5, 6],
    ['curl', 'rest curl κ', 0, 1, 0.01, 0.55],
    ['contact', 'contact k<sub>c</sub>', 20, 1000, 10, 250],
    ['friction', 'friction μ', 0, 1, 0.01, 0.3],
    ['self-contact', 'self-contact k<sub>sc</sub> (0 off)', 0, 3200, 50, 0],
  ],
  solver: [
    ['damping', 'damping β (1/s)', 0, 50, 0.5, 10],
    ['substeps', 'substeps per frame', 1, 100, 1, 22],
    ['gravity', 'gravity (top row held)', 0, 1, 1, 0],
    ['floor', 'floor (drop the patch on it)', 0, 1, 1, 0],
  ],
  patch: [
    ['width', 'width (stitches)', 4, 64, 1, 16],
    ['height', 'height (rows)', 4, 64, 1, 16],
  ],
};

function fail(reason) {
  yarnify.error = reason;
  document.getElementById('fallback-reason').textContent = reason;
  document.getElementById('fallback').hidden = false;
  statusLine.textContent = 'no WebGPU';
}

function showError(message) {
  yarnify.errors.push(message);
  statusLine.dataset.error = message;
}

function sizeCanvas() {
  const scale = window.devicePixelRatio || 1;
  const width = Math.max(1, Math.round(canvas.clientWidth * scale));
  const height = Math.max(1, Math.round(canvas.clientHeight * scale));
  const changed = canvas.width !== width || canvas.height !== height;
  canvas.width = width;
  canvas.height = height;
  return changed;
}

// The pattern selector, first in the patch's fieldset: every pattern the
// demo knits; choosing one rebuilds the patch, as a size change does.
function buildPatternSelect(app, rebuilt) {
  const label = document.createElement('label');
  label.innerHTML = '<span>pattern</span><select id="pattern"></select>';
  const select = label.querySelector('select');
  for (const name of patterns()) select.append(new Option(name, name));
  select.value = app.pattern();
  document.getElementById('patch').append(label);
  // A pattern in the address (e.g. ?pattern=garter) starts there.
  const given = new URLSearchParams(location.search).get('pattern');
  if (given !== null) {
    try {
      app.set_pattern(given);
      rebuilt();
    } catch (e) {
      showError(String(e.message ?? e));
    }
    select.value = app.pattern();
  }
  select.addEventListener('change', () => {
    try {
      app.set_pattern(select.value);
      rebuilt();
      delete statusLine.dataset.error;
    } catch (e) {
      showError(String(e.message ?? e));
    }
    select.value = app.pattern();
  });
}

// The on/off settings, drawn as checkboxes.
const CHECKBOXES = ['gravity', 'floor'];

// `rebuilt` runs after a change that built a fresh patch (its size or
// pattern, or the floor it was dropped on).
function buildControls(app, rebuilt) {
  buildPatternSelect(app, rebuilt);
  for (const [group, rows] of Object.entries(CONTROLS)) {
    const fieldset = document.getElementById(group);
    for (const [name, text, min, max, step, value] of rows) {
      const label = document.createElement('label');
      const checkbox = CHECKBOXES.includes(name);
      const rebuilds = group === 'patch' || name === 'floor';
      label.innerHTML = `<span>${text}</span>` + (checkbox
        ? `<input type="checkbox" id="${name}">`
        : `<output id="${name}-value">${value}</output>` +
          `<input type="range" id="${name}" min="${min}" max="${max}" step="${step}" value="${value}">`);
      fieldset.append(label);
      const input = label.querySelector('input');
      let last = value;
      // A setting in the address (e.g. ?width=32&substeps=10) starts there.
      const given = new URLSearchParams(location.search).get(name);
      if (given !== null) {
        try {
          app.set(name, Number(given));
          last = Number(given);
          if (rebuilds) rebuilt();
          if (checkbox) input.checked = last !== 0; else input.value = last;
          if (!checkbox) label.querySelector('output').textContent = String(last);
        } catch (e) {
          showError(String(e.message ?? e));
        }
      }
      input.addEventListener(checkbox ? 'change' : 'input', () => {
        const v = checkbox ? (input.checked ? 1 : 0) : Number(input.value);
        try {
          app.set(name, v);
          last = v;
          if (rebuilds) rebuilt();
          delete statusLine.dataset.error;
        } catch (e) {
          showError(String(e.message ?? e));
          if (checkbox) input.checked = last !== 0; else input.value = last;
        }
        if (!checkbox) label.querySelector('output').textContent = checkbox ? '' : String(last);
      });
    }
  }
}

async function run() {
  await init();
  sizeCanvas();
  let app;
  try {
    app = await start(canvas);
  } catch (e) {
    fail(`WebGPU is present, but no adapter or device could be opened: ${e.message ?? e}`);
    return;
  }
  const unravel = document.getElementById('unravel');
  let unravelling = false;
  // A fresh patch is not unravelling.
  const rebuilt = () => {
    unravelling = false;
    unravel.textContent = 'Unravel';
  };
  buildControls(app, rebuilt);
  // The browser names its adapter to the page, not always to wgpu.
  const info = (await navigator.gpu.requestAdapter())?.info;
  const adapterName = info && (info.description || [info.vendor, info.architecture].filter(Boolean).join(' '));
  document.getElementById('reset').onclick = () => {
    app.reset();
    rebuilt();
  };
  unravel.onclick = () => {
    unravelling = !unravelling;
    app.unravel(unravelling);
    unravel.textContent = unravelling ? 'Stop unravelling' : 'Unravel';
  };
  document.getElementById('ladder').onclick = () => app.ladder();

  // Left-drag on a loop grabs it (positions are read back only now);
  // elsewhere, or with another button, it orbits. The wheel zooms.
  let pointer = null;
  const pixel = (e) => [e.offsetX * canvas.width / canvas.clientWidth, e.offsetY * canvas.height / canvas.clientHeight];
  canvas.addEventListener('pointerdown', (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointer = { mode: 'pending', x: e.offsetX, y: e.offsetY, last: pixel(e) };
    const mine = pointer;
    if (e.button !== 0) { mine.mode = 'orbit'; return; }
    app.grab(...pixel(e)).then((node) => {
      if (pointer !== mine) { if (node >= 0) app.let_go(); return; }
      mine.mode = node >= 0 ? 'grab' : 'orbit';
      if (node >= 0) { canvas.classList.add('held'); app.drag(...mine.last); }
    }, (err) => showError(String(err.message ?? err)));
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!pointer) return;
    pointer.last = pixel(e);
    if (pointer.mode === 'grab') app.drag(...pointer.last);
    if (pointer.mode === 'orbit') app.orbit(-(e.offsetX - pointer.x) * 0.01, (e.offsetY - pointer.y) * 0.01);
    pointer.x = e.offsetX;
    pointer.y = e.offsetY;
  });
  const release = () => {
    if (pointer?.mode === 'grab') app.let_go();
    pointer = null;
    canvas.classList.remove('held');
  };
  canvas.addEventListener('pointerup', release);
  canvas.addEventListener('pointercancel', release);
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('wheel', (e) => { e.preventDefault(); app.zoom(Math.exp(-e.deltaY * 0.001)); }, { passive: false });

  Object.assign(yarnify, {
    ready: true,
    app,
    status: () => ({ ...JSON.parse(app.status()), adapterName }),
    positions: async () => Array.from(await app.positions()),
  });

  // The frame loop: several substeps a frame, nothing read back but what
  // the GPU raised, twice a second (app.check), which never waits.
  let window0 = { time: performance.now(), substeps: 0 };
  let checking = false;
  let status = JSON.parse(app.status());
  let previous = performance.now();
  function frame() {
    if (sizeCanvas()) app.resize(canvas.width, canvas.height);
    try {
      app.frame();
    } catch (e) {
      showError(String(e.message ?? e));
      statusLine.textContent = `stopped: ${e.message ?? e}`;
      return;
    }
    const now = performance.now();
    // Frame time: from one frame to the next, smoothed.
    yarnify.frameMs = yarnify.frameMs === 0 ? now - previous : 0.9 * yarnify.frameMs + 0.1 * (now - previous);
    previous = now;
    if (now - window0.time > 500) {
      if (!checking) {
        checking = true;
        app.check().catch((e) => showError(String(e.message ?? e))).finally(() => { checking = false; });
      }
      status = JSON.parse(app.status());
      yarnify.substepsPerSecond = (status.substeps - window0.substeps) / ((now - window0.time) / 1000);
      if (yarnify.substepsPerSecond < 0) yarnify.substepsPerSecond = 0;
      window0 = { time: now, substeps: status.substeps };
      const error = statusLine.dataset.error ? ` · error: ${statusLine.dataset.error}` : '';
      statusLine.innerHTML = `${adapterName || status.adapter} · ${status.pattern} · ${status.nodes} nodes · ` +
        `${status.alive}/${status.contacts} contacts · ` +
        `${Math.round(yarnify.substepsPerSecond)} substeps/s · frame ${yarnify.frameMs.toFixed(1)} ms` +
        (status.raised ? ` · ${status.raised}` : '') +
        `<span id="error">${error}</span>`;
    }
    requestAnimationFrame(frame);
  }
  requestAnimationFrame(frame);
}

if (!navigator.gpu) {
  fail('This browser does not offer WebGPU (navigator.gpu is missing), so the simulation cannot run here.');
} else {
  run().catch((e) => fail(`The demo could not start: ${e.message ?? e}`));
}
