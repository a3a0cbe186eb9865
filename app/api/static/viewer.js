// shapebag 3D viewer and "why it matched": two shapes side by side (orbit, zoom), coloured by their
// visual words (the same colour for the same word on both), keypoints marked, the two BoF histograms and
// the words that contribute most to their L1 distance. Data: GET /models/{id}/explain?against= or
// POST /explain. For a piece's hit, the search hit's `region` (the model's samples the piece matched)
// colours the hit: each vertex takes the weight of its nearest sample, as each sample stands for the
// surface nearest to it. three.js is vendored (/static/vendor/three.min.js, app/api/static/vendor/update.sh).
import * as THREE from "/static/vendor/three.min.js";

const PLAIN = [0.56, 0.66, 0.8]; // the thumbnails' steel blue
const KEYPOINT = 0xd7263d;
const MATCHED = [0.95, 0.38, 0.04];  // orange, far from the steel blue
const SVG = "http://www.w3.org/2000/svg";

// one colour per word, far apart for neighbouring ids (golden-ratio hues), the same on every shape
export function wordColour(word) {
  const hue = (word * 0.618033988749895) % 1;
  const c = new THREE.Color().setHSL(hue, 0.62, 0.55 - 0.1 * (word % 2));
  return [c.r, c.g, c.b];
}
export const wordCss = (word) => `rgb(${wordColour(word).map((x) => Math.round(x * 255)).join(",")})`;

function webglAvailable() {
  try {
    const canvas = document.createElement("canvas");
    return Boolean(canvas.getContext("webgl2") || canvas.getContext("webgl"));
  } catch (err) {
    return false;
  }
}

// ---- one 3D view ----------------------------------------------------------------------------------
function shapeGeometry(shape) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(shape.vertices), 3));
  geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(shape.faces), 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  const colours = new Float32Array(shape.words.length * 3);
  geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  return geometry;
}

// (n,) per vertex the weight of its nearest region sample, over the largest: 0 where nothing matched
export function regionWeights(vertices, region) {
  const n = vertices.length / 3;
  const out = new Float32Array(n);
  const peak = Math.max(...region.weights, 0);
  if (!(peak > 0)) return out;
  const samples = region.vertices.filter((v) => v < n);
  for (let i = 0; i < n; i++) {
    let best = Infinity;
    let weight = 0;
    for (let s = 0; s < samples.length; s++) {
      const v = samples[s];
      const dx = vertices[3 * i] - vertices[3 * v];
      const dy = vertices[3 * i + 1] - vertices[3 * v + 1];
      const dz = vertices[3 * i + 2] - vertices[3 * v + 2];
      const d = dx * dx + dy * dy + dz * dz;
      if (d < best) { best = d; weight = region.weights[s]; }
    }
    // a matched sample shows at least 3/4 strength: the colour says where, the shade how much
    out[i] = weight > 0 ? 0.75 + 0.25 * (weight / peak) : 0;
  }
  return out;
}

function paint(geometry, shape, mode) {
  const colours = geometry.getAttribute("color");
  if (mode === "region" && shape.region) {
    shape.region.forEach((w, i) => colours.setXYZ(i, ...PLAIN.map((c, j) => c + w * (MATCHED[j] - c))));
  } else {
    shape.words.forEach((word, i) => colours.setXYZ(i, ...(mode === "words" ? wordColour(word) : PLAIN)));
  }
  colours.needsUpdate = true;
}

function keypointCloud(shape) {
  const positions = new Float32Array(shape.keypoints.length * 3);
  shape.keypoints.forEach((v, i) => positions.set(shape.vertices.slice(3 * v, 3 * v + 3), 3 * i));
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
  const material = new THREE.PointsMaterial({ color: KEYPOINT, size: 6, sizeAttenuation: false, depthTest: false });
  return new THREE.Points(geometry, material);
}

class ShapeView {
  constructor(host, shape) {
    this.host = host;
    this.shape = shape;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    host.append(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.geometry = shapeGeometry(shape);
    this.mesh = new THREE.Mesh(this.geometry, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    this.points = keypointCloud(shape);
    this.scene.add(this.mesh, this.points);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a96a8, 1.6));
    const key = new THREE.DirectionalLight(0xffffff, 1.4);
    key.position.set(-0.6, 0.9, 0.9);
    this.scene.add(key);
    const radius = this.geometry.boundingSphere.radius || 1;
    this.camera = new THREE.PerspectiveCamera(35, 1, radius / 100, radius * 100);
    // the thumbnails' 3/4 view: 35 degrees round the vertical, 20 degrees from above
    const yaw = (-35 * Math.PI) / 180;
    const pitch = (20 * Math.PI) / 180;
    const d = radius * 3.4;
    this.camera.position.set(-d * Math.sin(yaw) * Math.cos(pitch), d * Math.sin(pitch), d * Math.cos(yaw) * Math.cos(pitch));
    this.controls = new THREE.OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.copy(this.geometry.boundingSphere.center);
    this.controls.update();
    this.controls.addEventListener("change", () => this.render());
    this.resizer = new ResizeObserver(() => this.resize());
    this.resizer.observe(host);
    this.setMode("words");
    this.resize();
  }

  setMode(mode) {
    paint(this.geometry, this.shape, mode);
    this.render();
  }

  showKeypoints(on) {
    this.points.visible = on;
    this.render();
  }

  resize() {
    const width = this.host.clientWidth || 300;
    const height = this.host.clientHeight || width;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() {
    this.renderer.render(this.scene, this.camera);
    this.host.dataset.rendered = "1"; // the browser test waits for this
  }

  dispose() {
    this.resizer.disconnect();
    this.controls.dispose();
    this.geometry.dispose();
    this.renderer.dispose();
  }
}

// ---- the explanation --------------------------------------------------------------------------------
function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (key === "class") node.className = value;
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value);
  }
  node.append(...children.filter((c) => c !== null && c !== undefined));
  return node;
}

function svg(tag, attrs) {
  const node = document.createElementNS(SVG, tag);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
  return node;
}

// both histograms as paired bars, one pair per word; the words that separate them most are outlined
function histogram(e) {
  const a = e.shape.bof;
  const b = e.against.bof;
  const top = new Set(e.top_words.map((w) => w.word));
  const width = 760;
  const height = 150;
  const step = width / a.length;
  const peak = Math.max(...a, ...b) || 1;
  const chart = svg("svg", { viewBox: `0 0 ${width} ${height + 16}`, class: "histogram", role: "img",
    "aria-label": "Bag-of-Features histograms of both shapes" });
  a.forEach((_, w) => {
    const x = w * step;
    if (top.has(w)) chart.append(svg("rect", { x, y: 0, width: step, height, class: "top-word" }));
    chart.append(svg("rect", { x: x + step * 0.12, y: height - (a[w] / peak) * height, width: step * 0.36,
      height: (a[w] / peak) * height, fill: wordCss(w), class: "bar-a" }));
    chart.append(svg("rect", { x: x + step * 0.52, y: height - (b[w] / peak) * height, width: step * 0.36,
      height: (b[w] / peak) * height, fill: wordCss(w), class: "bar-b" }));
    if (w % 8 === 0) chart.append(Object.assign(svg("text", { x: x + 1, y: height + 13, class: "tick" }), { textContent: w }));
  });
  return chart;
}

function topWords(e) {
  const rows = e.top_words.map((w) => el("tr", {},
    el("td", {}, el("span", { class: "swatch", style: `background:${wordCss(w.word)}` }), ` word ${w.word}`),
    el("td", {}, w.shape.toFixed(3)),
    el("td", {}, w.against.toFixed(3)),
    el("td", {}, w.contribution.toFixed(3)),
    el("td", {}, `${((100 * w.contribution) / (e.bof_l1 || 1)).toFixed(0)} %`),
  ));
  return el("table", { class: "top-words" },
    el("thead", {}, el("tr", {}, el("th", {}, "word"), el("th", {}, "query"), el("th", {}, "hit"),
      el("th", {}, "|a − b|"), el("th", {}, "of L1"))),
    el("tbody", {}, ...rows));
}

function panel(shape, role) {
  const host = el("div", { class: "view3d" });
  const label = shape.label ? el("span", { class: "chip" }, shape.label)
    : el("span", { class: "chip none" }, shape.model_id === null ? "uploaded" : "unlabelled");
  const head = el("div", { class: "view-head" }, el("strong", {}, role), " ", el("span", { class: "view-name" }, shape.name), " ", label);
  return { host, node: el("div", { class: "view-panel" }, head, host,
    el("div", { class: "view-foot" }, `${shape.words.length} vertices · ${shape.keypoints.length} keypoints`)) };
}

// Render the comparison into `container`; returns a dispose function. hit: the search hit (its
// partial scores and matched region, when the query was a piece), or nothing.
export function renderCompare(container, e, hit = null) {
  const left = panel(e.shape, "query");
  const right = panel(e.against, "hit");
  const region = hit && hit.region ? hit.region : null;
  if (region) e.against.region = regionWeights(e.against.vertices, region);
  const options = [el("option", { value: "words" }, "coloured by visual word"), el("option", { value: "plain" }, "plain")];
  if (region) options.unshift(el("option", { value: "region", selected: "" }, "the region that matched"));
  const mode = el("select", { class: "mode", "aria-label": "colouring" }, ...options);
  const keypoints = el("input", { type: "checkbox", checked: "" });
  const fused = Math.abs(e.distance - e.bof_l1) > 5e-4;  // the index also compares the Shape-DNA spectrum
  const summary = el("p", { class: "why" },
    `L1 distance between the Bag-of-Features histograms: ${e.bof_l1.toFixed(3)} over ${e.words} words`,
    fused ? ` (the ranked distance, BoF fused with the Shape-DNA spectrum, is ${e.distance.toFixed(3)}). ` : ". ",
    "The words in the table make up most of it; the same colour is the same word on both shapes, red dots are keypoints.");
  const pct = (x) => `${Math.round(100 * x)} %`;
  const partial = region ? el("p", { class: "why partial-why" },
    el("span", { class: "swatch matched" }), ` The query is a piece: ${pct(hit.forward)} of its surface is found in “${e.against.name}”,`,
    ` which it covers ${pct(hit.reverse)} of. Orange on the hit: where the query's surface matched (deeper: more of it);`,
    " a part repeated on the model (both legs, both arms) can light up for one part of the query.") : null;
  const views = el("div", { class: "views" }, left.node, right.node);
  container.replaceChildren(
    el("div", { class: "compare-head" }, el("h3", {}, `Why “${e.against.name}” matched`),
      el("label", {}, mode), el("label", {}, keypoints, " keypoints")),
    views, partial, summary,
    el("div", { class: "explain-row" }, el("div", { class: "chart" }, histogram(e),
      el("div", { class: "legend" }, "left bar: query · right bar: hit · outlined: the words that differ most")), topWords(e)),
  );
  if (!webglAvailable()) {
    for (const p of [left, right]) p.host.append(el("p", { class: "empty" }, "The 3D view needs WebGL, which this browser does not offer."));
    return () => {};
  }
  const shown = [new ShapeView(left.host, e.shape), new ShapeView(right.host, e.against)];
  if (region) shown.forEach((v) => v.setMode(mode.value));
  mode.addEventListener("change", () => shown.forEach((v) => v.setMode(mode.value)));
  keypoints.addEventListener("change", () => shown.forEach((v) => v.showKeypoints(keypoints.checked)));
  return () => shown.forEach((v) => v.dispose());
}
