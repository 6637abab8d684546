// The watercolour look's passes, run as the export's look/passes.json describes them (diffwash/_look_export.py):
// a light depth pass, a float G-buffer, three edge-blur passes and the final pass to the screen. One source for
// every page that draws the look: viewer.html has it pasted in by diffwash/_viewer.py, diffwash.widget's front
// end by diffwash/_widget.py. Float render targets need EXT_color_buffer_float: the caller checks for it.
//
// createLookRunner(gl, LOOK, mesh, fail): LOOK is the export's look as diffwash._viewer.look_config writes it
// (graph, shaders, uniforms, half-float textures, light frustum); mesh = {attributes: {POSITION, NORMAL, _MIX,
// _STROKE: Float32Array}, position, indices: Uint32Array, ibo: its element buffer}; fail(message) throws.
// runner.draw(values, light, size) draws a frame of `size` = [width, height] with every uniform in `values`
// (row-major matrices); runner.setTexture(name, data) replaces an input texture (data as LOOK.textures holds it).

// A column-major n x n matrix (WebGL's layout) as rows, the look's uniforms' layout (uniforms.json).
function rowsOf(m, n) {
  return Array.from({length: n}, (_, r) => Array.from({length: n}, (_, c) => m[c * n + r]));
}

// A compiled shader, or fail(message) with the compiler's log (the plain model's programs use it too).
function compileShader(gl, type, source, name, fail) {
  const sh = gl.createShader(type);
  gl.shaderSource(sh, source); gl.compileShader(sh);
  if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) fail(name + ": " + gl.getShaderInfoLog(sh));
  return sh;
}

function createLookRunner(gl, LOOK, mesh, fail) {
  const v3sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const v3scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const v3dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const v3cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const v3normalize = (a) => v3scale(a, 1 / Math.sqrt(v3dot(a, a)));
  const columnMajor = (rows) => new Float32Array(rows[0].map((_, c) => rows.map((row) => row[c])).flat());
  const halfFloats = (h) => {
    if (typeof h !== "string") return h;  // already a Uint16Array
    const s = atob(h), out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return new Uint16Array(out.buffer);
  };
  // diffwash.look.light_view_projection: an orthographic view along the light fitting the mesh's bounding sphere.
  function lightViewProjection(direction) {
    const d = v3normalize(direction), L = LOOK.light, c = L.centre, r = L.half_size;
    let k = 0;  // "up" is the world axis least aligned with the light
    for (let i = 1; i < 3; i++) if (Math.abs(d[i]) < Math.abs(d[k])) k = i;
    const axis = [0, 0, 0]; axis[k] = 1;
    const x = v3normalize(v3cross(axis, d)), y = v3cross(d, x);
    return [[...v3scale(x, 1 / r), -v3dot(x, c) / r], [...v3scale(y, 1 / r), -v3dot(y, c) / r],
            [...v3scale(d, L.depth_scale), -L.depth_scale * v3dot(d, c) + L.depth_offset], [0, 0, 0, 1]];
  }
  const FORMATS = {1: ["RED", "R"], 2: ["RG", "RG"], 3: ["RGB", "RGB"], 4: ["RGBA", "RGBA"]};
  const FILTERS = {nearest: ["NEAREST", "NEAREST"], linear: ["LINEAR", "LINEAR"], linear_mipmap_linear: ["LINEAR_MIPMAP_LINEAR", "LINEAR"]};
  function textureParameters(target, filter, wrap) {
    const [min, mag] = FILTERS[filter], w = wrap === "repeat" ? gl.REPEAT : gl.CLAMP_TO_EDGE;
    gl.texParameteri(target, gl.TEXTURE_MIN_FILTER, gl[min]); gl.texParameteri(target, gl.TEXTURE_MAG_FILTER, gl[mag]);
    gl.texParameteri(target, gl.TEXTURE_WRAP_S, w); gl.texParameteri(target, gl.TEXTURE_WRAP_T, w);
    if (target === gl.TEXTURE_3D) gl.texParameteri(target, gl.TEXTURE_WRAP_R, w);
  }
  // An input texture from its half floats (each level as the export's .npy holds it, row 0 first).
  function upload(spec, data, t) {
    const [format, prefix] = FORMATS[data.channels];
    gl.bindTexture(t.target, t.tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    data.levels.forEach((level, k) => {
      const values = halfFloats(level.half_float), s = level.shape;
      if (t.target === gl.TEXTURE_3D) gl.texImage3D(t.target, k, gl[prefix + "16F"], s[2], s[1], s[0], 0, gl[format], gl.HALF_FLOAT, values);
      else gl.texImage2D(t.target, k, gl[prefix + "16F"], s[1], s[0], 0, gl[format], gl.HALF_FLOAT, values);
    });
    gl.texParameteri(t.target, gl.TEXTURE_MAX_LEVEL, data.levels.length - 1);
    textureParameters(t.target, spec.filter, spec.wrap);
    return t;
  }
  const lookTexture = (spec, data) => upload(spec, data, {target: spec.kind === "3d" ? gl.TEXTURE_3D : gl.TEXTURE_2D, tex: gl.createTexture()});
  // A render target: a float colour texture (16-bit where 32-bit floats cannot be filtered) and a depth buffer.
  function lookTarget(spec, floatLinear) {
    const channels = spec.format.startsWith("RGBA") ? 4 : 1, [format, prefix] = FORMATS[channels];
    const half = spec.filter !== "nearest" && !floatLinear, [w, h] = spec.size, tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl[prefix + (half ? "16F" : "32F")], w, h, 0, gl[format], half ? gl.HALF_FLOAT : gl.FLOAT, null);
    textureParameters(gl.TEXTURE_2D, spec.filter, spec.wrap);
    const fbo = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    if (spec.depth) {
      const rb = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, rb); gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, w, h);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, rb);
    }
    if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) fail("the look's " + spec.format + " render target is incomplete");
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return {target: gl.TEXTURE_2D, tex: tex, fbo: fbo, size: spec.size};
  }
  const compile = (type, source, name) => compileShader(gl, type, source, name, fail);
  function lookProgram(pass) {
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl.VERTEX_SHADER, LOOK.shaders[pass.vertex], pass.vertex));
    gl.attachShader(p, compile(gl.FRAGMENT_SHADER, LOOK.shaders[pass.fragment], pass.fragment));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) fail(pass.name + " pass: " + gl.getProgramInfoLog(p));
    const uniforms = [];
    for (let i = 0; i < gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS); i++) {
      const info = gl.getActiveUniform(p, i);
      uniforms.push({name: info.name.replace(/\[0\]$/, ""), type: info.type, size: info.size, loc: gl.getUniformLocation(p, info.name)});
    }
    return {program: p, uniforms: uniforms};
  }
  // Every uniform the program declares, by its type (matrices arrive row-major, as in uniforms.json).
  function setUniforms(prog, values) {
    for (const u of prog.uniforms) {
      if (!(u.name in values)) continue;
      const v = values[u.name];
      if (u.type === gl.FLOAT) u.size > 1 ? gl.uniform1fv(u.loc, v) : gl.uniform1f(u.loc, v);
      else if (u.type === gl.FLOAT_VEC2) gl.uniform2fv(u.loc, v);
      else if (u.type === gl.FLOAT_VEC3) gl.uniform3fv(u.loc, v);
      else if (u.type === gl.FLOAT_VEC4) gl.uniform4fv(u.loc, v);
      else if (u.type === gl.INT || u.type === gl.BOOL) gl.uniform1i(u.loc, v ? +v : 0);
      else if (u.type === gl.FLOAT_MAT3) gl.uniformMatrix3fv(u.loc, false, columnMajor(v));
      else if (u.type === gl.FLOAT_MAT4) gl.uniformMatrix4fv(u.loc, false, columnMajor(v));
    }
  }

  const floatLinear = !!gl.getExtension("OES_texture_float_linear"), g = LOOK.graph;
  const passes = g.passes.map((pass) => Object.assign({}, pass, lookProgram(pass)));
  const inputs = {};
  for (const name in g.textures) inputs[name] = lookTexture(g.textures[name], LOOK.textures[name]);
  for (const name in g.render_targets) inputs[name] = lookTarget(g.render_targets[name], floatLinear);
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  for (const name in g.attributes) {
    const a = g.attributes[name], data = mesh.attributes[a.glb], b = gl.createBuffer();
    if (!data) fail("the mesh has no " + a.glb + " attribute");
    gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(a.location); gl.vertexAttribPointer(a.location, data.length / mesh.position.length * 3, gl.FLOAT, false, 0, 0);
  }
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.ibo);
  const empty = gl.createVertexArray();
  gl.bindVertexArray(null);
  let shadowLight = null;  // the light the shadow map was drawn for

  function runPass(pass, values, size) {
    const target = pass.target === "screen" ? null : inputs[pass.target];
    gl.bindFramebuffer(gl.FRAMEBUFFER, target ? target.fbo : null);
    const [w, h] = target ? target.size : size;
    gl.viewport(0, 0, w, h);
    if (pass.clear) {
      const c = pass.clear.colour;
      gl.clearColor(c[0], c[1], c[2], c[3]); gl.clearDepth(pass.clear.depth);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    }
    if (pass.depth_test) { gl.enable(gl.DEPTH_TEST); gl.depthFunc(gl.LESS); } else gl.disable(gl.DEPTH_TEST);
    if (pass.cull) { gl.enable(gl.CULL_FACE); gl.cullFace(gl.BACK); gl.frontFace(gl.CCW); } else gl.disable(gl.CULL_FACE);
    gl.useProgram(pass.program);
    setUniforms(pass, values);
    Object.entries(pass.inputs).forEach(([uniform, name], unit) => {
      const t = inputs[name], u = pass.uniforms.find((x) => x.name === uniform);
      gl.activeTexture(gl.TEXTURE0 + unit); gl.bindTexture(t.target, t.tex);
      if (u) gl.uniform1i(u.loc, unit);
    });
    if (pass.draw === "mesh") { gl.bindVertexArray(vao); gl.drawElements(gl.TRIANGLES, mesh.indices.length, gl.UNSIGNED_INT, 0); }
    else { gl.bindVertexArray(empty); gl.drawArrays(gl.TRIANGLES, 0, 3); }
    gl.bindVertexArray(null);
    for (let unit = 0; unit < Object.keys(pass.inputs).length; unit++) {
      gl.activeTexture(gl.TEXTURE0 + unit); gl.bindTexture(gl.TEXTURE_2D, null); gl.bindTexture(gl.TEXTURE_3D, null);
    }
  }
  function draw(values, light, size) {
    const all = Object.assign({}, values, {look_light_view_projection: lightViewProjection(light)});
    for (const pass of passes) {
      if (pass.when === "light") {
        if (shadowLight !== null && shadowLight.every((v, i) => v === light[i])) continue;
        shadowLight = light.slice();
      }
      runPass(pass, all, size);
    }
  }
  function setTexture(name, data) {
    if (!(name in g.textures)) fail("the look has no input texture " + name);
    upload(g.textures[name], data, inputs[name]);
  }
  return {draw: draw, setTexture: setTexture, lightViewProjection: lightViewProjection};
}
