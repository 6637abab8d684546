// diffwash.widget's front end (anywidget ES module): the scene drawn with the exported WebGL2 shaders.
//
// The shaders, the camera and the slider ranges come from Python in the `config` trait (diffwash/_widget.py);
// the mesh arrives once as bytes (`mesh`), the LUT as bytes whenever Python re-bakes it (`lut`, `lut_range`).
// A slider of a uniform (shininess, gain, bias, wash reduction, the light) redraws at once, without Python;
// a slider of a range constant or a pigment sets its trait and Python sends the re-baked LUT back.
// A scene with a watercolour look is drawn with the look's passes: createLookRunner, from look-runner.js, which
// diffwash/_widget.py puts before this file (the same source viewer.html runs). A look slider sets its uniform at
// once; Python answers with the uniforms that derive from it (`look_uniforms`) and, after a pigment change, the
// look's 3D mix LUT (`mix_lut`).
// For scripts and tests, `el.diffwash` (and `window.diffwashWidgets`) hold the widget's state and controls.

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalize = (a) => scale(a, 1 / Math.sqrt(dot(a, a)));
const rotate = (v, k, t) => add(add(scale(v, Math.cos(t)), scale(cross(k, v), Math.sin(t))), scale(k, dot(k, v) * (1 - Math.cos(t))));

// World to eye (diffwash._camera.look_at), eye to clip (diffwash._camera.perspective), column-major.
function lookAt(eye, target, up) {
  const f = normalize(sub(target, eye)), s = normalize(cross(f, up)), u = cross(s, f), r = [s, u, scale(f, -1)];
  const m = new Float64Array(16);
  for (let i = 0; i < 3; i++) { for (let j = 0; j < 3; j++) m[j * 4 + i] = r[i][j]; m[12 + i] = -dot(r[i], eye); }
  m[15] = 1;
  return m;
}
function perspective(fovY, aspect, near, far) {
  const f = 1 / Math.tan(fovY * Math.PI / 360), m = new Float64Array(16);
  m[0] = f / aspect; m[5] = f; m[10] = (far + near) / (near - far); m[11] = -1; m[14] = 2 * far * near / (near - far);
  return m;
}
function mul(a, b) {
  const m = new Float64Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; m[c * 4 + r] = s;
  }
  return m;
}
// Bytes traits arrive as a DataView (anywidget), an ArrayBuffer or a typed array.
function u8(data) {
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
}
// A copy, aligned for the typed array type.
const view = (bytes, start, count, Type) => new Type(bytes.slice(start, start + count * Type.BYTES_PER_ELEMENT).buffer);

function createGL(canvas, config) {
  const gl = canvas.getContext("webgl2", {antialias: false, alpha: false, preserveDrawingBuffer: true, premultipliedAlpha: false});
  if (!gl) throw new Error("diffwash.widget needs WebGL2");
  const compile = (type, source, name) => compileShader(gl, type, source, name, (msg) => { throw new Error(msg); });  // look-runner.js
  const programs = {};
  for (const mode in config.shaders) {
    const src = config.shaders[mode], p = gl.createProgram();
    gl.attachShader(p, compile(gl.VERTEX_SHADER, src.vert, src.names[0]));
    gl.attachShader(p, compile(gl.FRAGMENT_SHADER, src.frag, src.names[1]));
    gl.bindAttribLocation(p, 0, "position"); gl.bindAttribLocation(p, 1, "normal");
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(mode + " program: " + gl.getProgramInfoLog(p));
    const loc = {};
    for (let i = 0; i < gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS); i++) {
      const name = gl.getActiveUniform(p, i).name;
      loc[name] = gl.getUniformLocation(p, name);
    }
    programs[mode] = {program: p, loc: loc};
  }
  const tex = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, tex);
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]]) gl.texParameteri(gl.TEXTURE_2D, k, v);
  return {gl: gl, programs: programs, lut: tex, vao: null, count: 0};
}

function uploadMesh(g, config, data) {
  const gl = g.gl, bytes = u8(data), n = config.vertices * 3;
  const position = view(bytes, 0, n, Float32Array), normal = view(bytes, 4 * n, n, Float32Array);
  const indices = view(bytes, 8 * n, config.faces * 3, Uint32Array);
  g.vao = gl.createVertexArray();
  gl.bindVertexArray(g.vao);
  [[0, position], [1, normal]].forEach(([loc, values]) => {
    const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, values, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
  });
  const ibo = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ibo);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
  gl.bindVertexArray(null);
  g.count = indices.length;
  g.mesh = {position: position, normal: normal, indices: indices, ibo: ibo};
}

// The look's passes over the same mesh, with its per-vertex attributes (`look_mesh`: each float32, in turn); null
// with the reason where this WebGL2 cannot draw them.
function createLook(g, config, data) {
  if (!config.look) return {runner: null, why: ""};
  if (!g.gl.getExtension("EXT_color_buffer_float")) {
    return {runner: null, why: "this browser's WebGL2 has no EXT_color_buffer_float (float render targets), which the watercolour look needs: showing the plain model"};
  }
  const bytes = u8(data), attributes = {POSITION: g.mesh.position, NORMAL: g.mesh.normal};
  let offset = 0;
  for (const [name, comps] of config.look.attributes) {
    const n = config.vertices * comps;
    attributes[name] = view(bytes, offset, n, Float32Array); offset += 4 * n;
  }
  const mesh = Object.assign({attributes: attributes}, g.mesh);
  return {runner: createLookRunner(g.gl, config.look, mesh, (msg) => { throw new Error(msg); }), why: ""};
}
function uploadMixLut(look, config, data) {
  const spec = config.look.textures.mix_lut, shape = spec.levels[0].shape, n = shape.reduce((a, b) => a * b, 1) * spec.channels;
  look.setTexture("mix_lut", {channels: spec.channels, levels: [{shape: shape, half_float: view(u8(data), 0, n, Uint16Array)}]});
}
function drawLook(look, config, s) {
  const cam = config.camera, leaves = {};
  for (const k in s.lookValues) leaves["look_" + k] = s.lookValues[k];
  const vp = mul(perspective(cam.fov_y, config.width / config.height, s.near, s.far), lookAt(s.eye, cam.target, cam.up));
  const values = Object.assign({}, config.look.uniforms, s.constants, s.lookUniforms, leaves, {
    light_direction: s.light, eye: s.eye, view_projection: rowsOf(vp, 4), eye_forward: normalize(sub(cam.target, s.eye))});
  look.draw(values, s.light, [config.width, config.height]);
}

// The LUT: sRGB-encoded half floats, top row first (v = 0), linear filtering, clamped, as the shaders expect.
function uploadLut(g, size, data) {
  const gl = g.gl;
  gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, g.lut);
  gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false); gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  const values = view(u8(data), 0, size * size * 3, Uint16Array);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB16F, size, size, 0, gl.RGB, gl.HALF_FLOAT, values);
}

function draw(g, config, s) {
  const gl = g.gl, p = g.programs[s.shading], bg = s.background, cam = config.camera;
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  gl.viewport(0, 0, config.width, config.height);
  gl.clearColor(bg[0], bg[1], bg[2], 1); gl.clearDepth(1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST); gl.depthFunc(gl.LESS);
  if (config.two_sided) gl.disable(gl.CULL_FACE); else { gl.enable(gl.CULL_FACE); gl.cullFace(gl.BACK); gl.frontFace(gl.CCW); }
  gl.useProgram(p.program);
  const L = p.loc, f1 = (name, v) => { if (L[name]) gl.uniform1f(L[name], v); };
  const vp = mul(perspective(cam.fov_y, config.width / config.height, s.near, s.far), lookAt(s.eye, cam.target, cam.up));
  gl.uniformMatrix4fv(L.view_projection, false, new Float32Array(vp));
  gl.uniformMatrix4fv(L.model, false, new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]));
  if (L.normal_matrix) gl.uniformMatrix3fv(L.normal_matrix, false, new Float32Array([1, 0, 0, 0, 1, 0, 0, 0, 1]));
  for (const name in s.constants) f1(name, s.constants[name]);
  f1("lut_wash_max", s.lutRange[0]); f1("lut_unlit_max", s.lutRange[1]);
  if (L.light_direction) gl.uniform3fv(L.light_direction, s.light);
  if (L.eye) gl.uniform3fv(L.eye, s.eye);
  if (L.two_sided) gl.uniform1i(L.two_sided, config.two_sided ? 1 : 0);
  gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, g.lut);
  if (L.lut) gl.uniform1i(L.lut, 0);
  gl.bindVertexArray(g.vao);
  gl.drawElements(gl.TRIANGLES, g.count, gl.UNSIGNED_INT, 0);
  gl.bindVertexArray(null);
}

// ---- the panel ------------------------------------------------------------------------------------
function element(tag, attrs, parent, text) {
  const e = document.createElement(tag);
  for (const k in attrs || {}) e.setAttribute(k, attrs[k]);
  if (text !== undefined) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}
const fmt = (v) => (Math.abs(v) >= 100 || v === 0 ? v.toFixed(1) : v.toPrecision(3));
// A labelled range input; log sliders move the exponent. `set(v)` shows a value, `onInput(v)` reports one.
function slider(parent, spec, value, onInput) {
  const row = element("label", {class: "dw-row"}, parent);
  element("span", {class: "dw-name"}, row, spec.label);
  const lo = spec.log ? Math.log10(spec.min) : spec.min, hi = spec.log ? Math.log10(spec.max) : spec.max;
  const input = element("input", {type: "range", min: lo, max: hi, step: spec.log ? (hi - lo) / 2000 : (spec.step || (hi - lo) / 400)}, row);
  input.dataset.key = spec.key;
  const out = element("span", {class: "dw-value"}, row);
  const set = (v) => { input.value = spec.log ? Math.log10(Math.max(v, spec.min)) : v; out.textContent = fmt(v); };
  input.addEventListener("input", () => { const v = spec.log ? Math.pow(10, +input.value) : +input.value; out.textContent = fmt(v); onInput(v); });
  set(value);
  return {input: input, set: set};
}

function lightAngles(l, cam) {
  const up = normalize(cam.up), n = normalize(l), f0 = normalize(sub(cam.eye, cam.target));
  const x0 = normalize(cross(up, f0)), z0 = cross(x0, up);
  return [Math.atan2(dot(n, x0), dot(n, z0)) * 180 / Math.PI, Math.asin(Math.max(-1, Math.min(1, dot(n, up)))) * 180 / Math.PI];
}
function lightFromAngles(az, el, cam) {
  const up = normalize(cam.up), f0 = normalize(sub(cam.eye, cam.target)), x0 = normalize(cross(up, f0)), z0 = cross(x0, up);
  const a = az * Math.PI / 180, e = el * Math.PI / 180;
  return add(add(scale(x0, Math.cos(e) * Math.sin(a)), scale(z0, Math.cos(e) * Math.cos(a))), scale(up, Math.sin(e)));
}

// A glaze's state with one slider's value in it ("K.0", "mix.P1", "amount"): a new object, so the model sees a change.
function withValue(state, key, v) {
  const out = JSON.parse(JSON.stringify(state)), [head, tail] = key.split(".");
  if (tail === undefined) out[head] = v;
  else if (head === "mix") out.mix[tail] = v;
  else out[head][+tail] = v;
  return out;
}
function valueOf(state, key) {
  const [head, tail] = key.split(".");
  return tail === undefined ? state[head] : head === "mix" ? state.mix[tail] : state[head][+tail];
}

// A slider that re-bakes sends its change at once unless a bake is under way; then only the latest value, once the
// table comes back (a drag does not queue a bake per input event in the kernel).
function rebakeSender(model) {
  const b = {waiting: false, dirty: false, timer: null};
  b.save = () => {
    if (b.waiting) { b.dirty = true; return; }
    b.waiting = true; model.save_changes();
    clearTimeout(b.timer); b.timer = setTimeout(b.done, 2000);  // no answer (a value Python refused): go on
  };
  b.done = () => { b.waiting = false; clearTimeout(b.timer); if (b.dirty) { b.dirty = false; b.save(); } };
  return b;
}

function buildPanel(panel, model, config, s, rebake, redraw, look) {
  const controls = {constants: {}, wash: {}, unlit: {}, look: {}};
  if (config.look) {
    const box = element("fieldset", {}, panel);
    element("legend", {}, box, "watercolour look");
    const label = element("label", {class: "dw-radio"}, box);
    const on = element("input", {type: "checkbox"}, label);
    label.appendChild(document.createTextNode(" draw the look"));
    on.checked = s.lookOn; on.disabled = !look;
    on.addEventListener("change", () => { s.lookOn = on.checked; syncModes(); redraw(); });
    controls.lookOn = on;
    for (const spec of config.look.sliders) {
      const sl = slider(box, spec, s.lookValues[spec.key], (v) => {
        s.lookValues[spec.key] = v; redraw();
        model.set("look", Object.assign({}, model.get("look"), {[spec.key]: v})); model.save_changes();
      });
      sl.input.title = spec.doc; sl.input.disabled = !look;
      controls.look[spec.key] = sl;
    }
  }
  // The look's geometry pass computes the thicknesses per pixel: the mode radios wait while it is drawn.
  const syncModes = () => { for (const mode of Object.keys(config.shaders)) if (controls["shading-" + mode]) controls["shading-" + mode].disabled = !!(look && s.lookOn); };
  controls.syncModes = syncModes;
  const modes = element("fieldset", {}, panel);
  element("legend", {}, modes, "thickness");
  for (const mode of Object.keys(config.shaders)) {
    const label = element("label", {class: "dw-radio"}, modes);
    const r = element("input", {type: "radio", name: "dw-shading-" + s.id, value: mode}, label);
    label.appendChild(document.createTextNode(" " + mode));
    r.checked = mode === s.shading;
    r.addEventListener("change", () => { model.set("shading", mode); model.save_changes(); });
    controls["shading-" + mode] = r;
  }
  const light = element("fieldset", {}, panel);
  element("legend", {}, light, "light");
  const [az, el] = lightAngles(s.light, config.camera);
  const onLight = () => {
    model.set("light", lightFromAngles(+controls.azimuth.input.value, +controls.elevation.input.value, config.camera));
    model.save_changes();
  };
  controls.azimuth = slider(light, {key: "azimuth", label: "azimuth", min: -180, max: 180, step: 0.5}, az, onLight);
  controls.elevation = slider(light, {key: "elevation", label: "elevation", min: -89, max: 89, step: 0.5}, el, onLight);
  const constants = element("fieldset", {}, panel);
  element("legend", {}, constants, "constants (k_*: re-bake)");
  for (const spec of config.constants) {
    controls.constants[spec.key] = slider(constants, spec, s.constants[spec.key], (v) => {
      model.set("constants", Object.assign({}, model.get("constants"), {[spec.key]: v}));
      if (spec.rebake) rebake.save(); else model.save_changes();
    });
  }
  if (config.paper) {
    const box = element("fieldset", {}, panel);
    element("legend", {}, box, "paper (re-bake)");
    controls.paper = {};
    config.paper.forEach((spec, i) => {
      controls.paper[i] = slider(box, spec, model.get("paper")[i], (v) => {
        const paper = model.get("paper").slice(); paper[i] = v;
        model.set("paper", paper); rebake.save();
      });
    });
  }
  for (const glaze of ["wash", "unlit"]) {
    const box = element("fieldset", {}, panel), info = config.pigments[glaze];
    element("legend", {}, box, glaze + ": " + info.name + " (re-bake)");
    for (const spec of info.sliders) {
      controls[glaze][spec.key] = slider(box, spec, valueOf(model.get(glaze), spec.key), (v) => {
        model.set(glaze, withValue(model.get(glaze), spec.key, v)); rebake.save();
      });
    }
  }
  const out = element("fieldset", {}, panel);
  element("legend", {}, out, "export");
  const folder = element("input", {type: "text", class: "dw-folder", value: model.get("export_folder")}, out);
  folder.addEventListener("change", () => { model.set("export_folder", folder.value); model.save_changes(); });
  const button = element("button", {type: "button", class: "dw-export"}, out, "export scene and LUT");
  button.addEventListener("click", () => model.send({type: "export"}));
  controls.folder = folder; controls.button = button;
  controls.status = element("div", {class: "dw-status"}, panel);
  controls.info = element("div", {class: "dw-info"}, panel);
  syncModes();
  return controls;
}

let count = 0;

function render({model, el}) {
  const config = model.get("config"), cam = config.camera;
  const s = {id: ++count, shading: model.get("shading"), constants: Object.assign({}, model.get("constants")),
             light: model.get("light").slice(), lutRange: model.get("lut_range").slice(),
             eye: cam.eye.slice(), near: cam.near, far: cam.far, background: model.get("background").slice()};
  const root = element("div", {class: "diffwash-widget"}, el);
  const canvas = element("canvas", {width: config.width, height: config.height, class: "dw-canvas"}, root);
  canvas.style.width = config.width + "px"; canvas.style.height = config.height + "px";
  const panel = element("div", {class: "dw-panel"}, root);
  let g;
  try {
    g = createGL(canvas, config);
  } catch (e) {
    element("div", {class: "dw-error"}, panel, String(e.message || e));
    throw e;
  }
  uploadMesh(g, config, model.get("mesh"));
  uploadLut(g, config.lut_size, model.get("lut"));
  const made = createLook(g, config, model.get("look_mesh")), look = made.runner;
  if (look && model.get("mix_lut").byteLength) uploadMixLut(look, config, model.get("mix_lut"));
  s.lookOn = !!look; s.lookValues = Object.assign({}, model.get("look")); s.lookUniforms = Object.assign({}, model.get("look_uniforms"));
  const api = {frames: 0, state: s, canvas: canvas, gl: g.gl, waiters: [], look: !!look};
  // Draw now (the test's frame rate), or on the next animation frame (the panel's changes, at most one per frame).
  api.draw = () => {
    if (look && s.lookOn) drawLook(look, config, s); else draw(g, config, s);
    api.frames += 1;
    const waiting = api.waiters; api.waiters = [];
    waiting.forEach((f) => f());
  };
  // One pixel read back: returns once the GPU has finished the frame.
  api.sync = () => { const px = new Uint8Array(4); g.gl.readPixels(0, 0, 1, 1, g.gl.RGBA, g.gl.UNSIGNED_BYTE, px); return px; };
  api.nextFrame = () => new Promise((resolve) => api.waiters.push(() => { api.sync(); resolve(performance.now()); }));
  let pending = false;
  const redraw = () => { if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; api.draw(); }); } };
  api.redraw = redraw;
  const rebake = rebakeSender(model);
  const controls = buildPanel(panel, model, config, s, rebake, redraw, look);
  api.controls = controls;
  const status = () => {
    controls.status.textContent = model.get("status");
    controls.info.textContent = `${config.faces} triangles; LUT ${config.lut_size}\u00b2, last bake ${model.get("bake_ms").toFixed(0)} ms` +
      (config.look ? (look ? "; the watercolour look's passes" : "; " + made.why) : "") +
      `; diffwash ${config.version}`;
  };
  status();
  const on = (name, f) => { model.on("change:" + name, f); return () => model.off("change:" + name, f); };
  const off = [
    on("constants", () => {
      s.constants = Object.assign({}, model.get("constants"));
      for (const k in controls.constants) controls.constants[k].set(s.constants[k]);
      redraw();
    }),
    on("light", () => {
      s.light = model.get("light").slice();
      const [a, e] = lightAngles(s.light, cam);
      controls.azimuth.set(a); controls.elevation.set(e);
      redraw();
    }),
    on("shading", () => { s.shading = model.get("shading"); controls["shading-" + s.shading].checked = true; redraw(); }),
    on("lut", () => { s.lutRange = model.get("lut_range").slice(); uploadLut(g, config.lut_size, model.get("lut")); redraw(); }),
    on("lut_range", () => { s.lutRange = model.get("lut_range").slice(); redraw(); }),
    on("wash", () => { for (const k in controls.wash) controls.wash[k].set(valueOf(model.get("wash"), k)); }),
    on("unlit", () => { for (const k in controls.unlit) controls.unlit[k].set(valueOf(model.get("unlit"), k)); }),
    on("status", status), on("bake_ms", () => { rebake.done(); status(); }),
    on("background", () => { s.background = model.get("background").slice(); redraw(); }),
    on("paper", () => { if (controls.paper) for (const k in controls.paper) controls.paper[k].set(model.get("paper")[+k]); }),
    on("mix_lut", () => { if (look) { uploadMixLut(look, config, model.get("mix_lut")); redraw(); } }),
    on("look_uniforms", () => { s.lookUniforms = Object.assign({}, model.get("look_uniforms")); redraw(); }),
    on("look", () => {
      s.lookValues = Object.assign({}, model.get("look"));
      for (const k in controls.look) controls.look[k].set(s.lookValues[k]);
      redraw();
    }),
    on("export_folder", () => { controls.folder.value = model.get("export_folder"); }),
  ];
  // Left-drag orbits the camera about its target (the first frame is the scene's camera).
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = {x: e.clientX, y: e.clientY}; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const up = normalize(cam.up), dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag = {x: e.clientX, y: e.clientY};
    let d = rotate(sub(s.eye, cam.target), up, -dx * 0.01);
    const d2 = rotate(d, normalize(cross(up, d)), -dy * 0.01);
    if (Math.abs(dot(normalize(d2), up)) < 0.995) d = d2;
    s.eye = add(cam.target, d);
    const c = Math.sqrt(dot(sub(config.centre, s.eye), sub(config.centre, s.eye)));
    s.far = (c + config.radius) * 1.01; s.near = Math.max(c - config.radius, s.far * 1e-3) * 0.99;
    redraw();
  });
  const endDrag = () => { drag = null; };
  canvas.addEventListener("pointerup", endDrag); canvas.addEventListener("pointercancel", endDrag);
  el.diffwash = api;
  (window.diffwashWidgets = window.diffwashWidgets || []).push(api);
  api.draw();
  return () => { off.forEach((f) => f()); const list = window.diffwashWidgets; list.splice(list.indexOf(api), 1); };
}

export default {render};
