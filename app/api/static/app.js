// shapebag web page: search by upload, browse the collection, similar models. Vanilla JS, no build.
"use strict";

const PAGE_SIZE = 24;
const state = { offset: 0, count: 0, label: "", status: "", labels: new Set(), ticket: 0, disposeCompare: null };
const $ = (id) => document.getElementById(id);

// ---- API ------------------------------------------------------------------------------------------
async function api(path, options = {}) {
  let response;
  try {
    response = await fetch(path, options);
  } catch (err) {
    throw new Error(`the service cannot be reached (${err.message})`);
  }
  const type = response.headers.get("content-type") || "";
  const body = type.includes("application/json") ? await response.json() : null;
  if (!response.ok) {
    const message = body && body.error ? body.error.message : `${response.status} ${response.statusText}`;
    const error = new Error(message);
    error.status = response.status;
    throw error;
  }
  return body;
}

function showError(message) {
  $("error-text").textContent = message;
  $("error").hidden = false;
}

function clearError() {
  $("error").hidden = true;
}

// ---- small DOM helpers ------------------------------------------------------------------------------
function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (key === "class") node.className = value;
    else if (key === "dataset") Object.assign(node.dataset, value);
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value);
  }
  for (const child of children.flat()) {
    if (child !== null && child !== undefined) node.append(child);
  }
  return node;
}

const thumbUrl = (id) => `/models/${id}/thumbnail.png`;
const fmtSeconds = (s) => (s >= 1 ? `${s.toFixed(2)} s` : `${Math.max(1, Math.round(s * 1000))} ms`);
const fmtBytes = (n) => (n > 1048576 ? `${(n / 1048576).toFixed(1)} MiB` : `${Math.ceil(n / 1024)} KiB`);  // binary units, as the 413 says

function thumb(src, alt, lazy = false) {
  // a placeholder until the server's rendering arrives (the first one of a model takes a moment), and
  // words instead of a blank square when there is none; lazy only in the long browse grid
  const box = el("div", { class: "thumb pending", title: "rendering…" });
  if (!src) { box.className = "thumb failed"; box.title = "no preview"; return box; }
  const img = el("img", lazy ? { alt, loading: "lazy", decoding: "async" } : { alt, decoding: "async" });
  img.addEventListener("load", () => { box.className = "thumb"; box.title = ""; });
  img.addEventListener("error", () => { img.classList.add("broken"); box.className = "thumb failed"; box.title = "no preview"; });
  img.src = src;
  box.append(img);
  return box;
}

function labelChip(label) {
  return label ? el("span", { class: "chip" }, label) : el("span", { class: "chip none" }, "unlabelled");
}

// a piece's two scores (partial matching): how much of the query is in the model, how much of the model it covers
function shares(hit) {
  if (!hit.partial || hit.forward === null || hit.forward === undefined) return null;
  const pct = (x) => `${Math.round(100 * x)} %`;
  const parts = [el("span", { class: "forward" }, `found ${pct(hit.forward)}`), " · ", el("span", { class: "reverse" }, `covers ${pct(hit.reverse)}`)];
  // fitted onto this model by a similarity: the query is a piece of it (docs/partial.md)
  if (hit.fit && hit.fit.lies_on) {
    parts.push(" · ", el("span", { class: "fit", title: `fitted onto this model${hit.fit.mirrored ? " (mirrored)" : ""}: ${pct(hit.fit.covered)} of the query within a vertex spacing of its surface` },
      `a piece of it (${pct(hit.fit.share)})`));
  }
  return el("div", { class: "shares", title: "partial match: the share of the query found in this model, and the share of this model the query covers" }, ...parts);
}

// ---- results (Figure 1 layout: query card, then the ranked hits) -------------------------------------
function renderResults(container, query, response) {
  container.replaceChildren();
  const seconds = response.seconds || {};
  const timing = [];
  if (seconds.describe !== undefined) timing.push(`described in ${fmtSeconds(seconds.describe)}`);
  if (seconds.search !== undefined) timing.push(`searched in ${fmtSeconds(seconds.search)}`);
  if (seconds.total !== undefined) timing.push(`total ${fmtSeconds(seconds.total)}`);

  const queryCard = el("div", { class: "card query" },
    el("div", { class: "rank q" }, "query"),
    thumb(query.thumbnail, query.name),
    el("div", { class: "meta" },
      el("div", { class: "name", title: query.name }, query.name),
      query.label !== undefined ? labelChip(query.label) : el("span", { class: "chip none" }, query.detail || ""),
    ),
  );
  const byModel = query.modelId !== undefined;  // a search by a stored model: its label is known
  const hits = response.data.map((hit) => {
    const same = byModel && query.label && hit.label === query.label;
    const neighbours = el("button", {
      class: "similar-link", title: "models similar to this one",
      onclick: (event) => { event.stopPropagation(); showSimilar(hit.model_id); },
    }, "similar ›");
    return el("div", {
      class: `card hit${same ? " same" : ""}`, dataset: { modelId: hit.model_id }, tabindex: "0",
      title: "open in 3D: why it matched", onclick: () => openCompare(container, query, hit),
      onkeydown: (event) => { if (event.key === "Enter") openCompare(container, query, hit); },
    },
      el("div", { class: "rank" }, `#${hit.rank}`),
      same ? el("div", { class: "mark same-label", title: `same label as the query (${query.label})` }, "✓ same label") : null,
      hit.relation ? el("div", { class: "mark variant", title: "a verified variant of the query (Variants above)" }, hit.relation) : null,
      hit.matched_object ? el("div", { class: "mark variant", title: "a file of several objects: the query matched one of them (1 = the largest)" }, `object ${hit.matched_object} of the file`) : null,
      thumb(thumbUrl(hit.model_id), hit.name),
      el("div", { class: "meta" },
        el("div", { class: "name", title: hit.name }, hit.name),
        labelChip(hit.label),
        el("div", { class: "row" }, el("span", { class: "distance" }, `L1 ${hit.distance.toFixed(3)}`), neighbours),
        shares(hit),
      ),
    );
  });
  const shared = byModel && query.label ? response.data.filter((h) => h.label === query.label).length : null;
  const heading = el("div", { class: "results-head" },
    el("h2", {}, `Top ${response.count} for “${query.name}”`),
    shared !== null ? el("span", { class: "shared" }, `${shared} of ${response.count} share its label “${query.label}”`) : null,
    el("span", { class: "timing" }, timing.join(" · ")),
  );
  const body = response.count
    ? el("div", { class: "results-row" }, queryCard, el("div", { class: "hits" }, hits))
    : el("div", { class: "results-row" }, queryCard, el("p", { class: "empty" }, "No indexed model to compare with yet."));
  const hint = response.count ? el("p", { class: "hint" }, "Click a result to see both shapes in 3D and why they matched.") : null;
  container.append(el("section", { class: "results", id: container.id + "-section" }, heading, body, hint),
    el("section", { class: "compare", id: container.id + "-compare", hidden: "" }));
}

// ---- 3D viewer + why it matched, in the same tab, under the results ---------------------------------------
async function openCompare(container, query, hit) {
  clearError();
  const out = container.querySelector(".compare");
  if (state.disposeCompare) { state.disposeCompare(); state.disposeCompare = null; }
  out.hidden = false;
  out.replaceChildren(el("div", { class: "loading" }, el("span", { class: "spinner" }), `Comparing with ${hit.name}…`));
  out.scrollIntoView({ behavior: "smooth", block: "start" });
  for (const card of container.querySelectorAll(".card.hit")) card.classList.toggle("selected", card === document.activeElement || +card.dataset.modelId === hit.model_id);
  try {
    let explanation;
    if (query.modelId !== undefined) {
      explanation = await api(`/models/${query.modelId}/explain?against=${hit.model_id}`);
    } else {
      const form = new FormData();
      form.append("file", query.file, query.file.name);
      form.append("against", String(hit.model_id));
      explanation = await api("/explain", { method: "POST", body: form });
    }
    const viewer = await import("/static/viewer.js");
    state.disposeCompare = viewer.renderCompare(out, explanation, hit);
    out.scrollIntoView({ block: "start" });
  } catch (err) {
    out.replaceChildren();
    out.hidden = true;
    showError(`Could not compare with ${hit.name}: ${err.message}`);
  }
}

// ---- search by upload ----------------------------------------------------------------------------------
async function runSearch(file) {
  clearError();
  const out = $("search-results");
  // elapsed seconds while the server works: a large mesh takes a while (upload, resample, eigen-solve, encode)
  const started = performance.now();
  const progress = el("span", { class: "elapsed" }, `Describing ${file.name}…`);
  out.replaceChildren(el("div", { class: "loading" }, el("span", { class: "spinner" }), progress));
  const ticker = setInterval(() => {
    const s = Math.round((performance.now() - started) / 1000);
    progress.textContent = `Describing ${file.name}… ${s} s (upload, resample, eigen-solve, encode)`;
  }, 1000);
  const query = { name: file.name, thumbnail: "", detail: fmtBytes(file.size), file };

  const form = new FormData();
  form.append("file", file, file.name);
  form.append("k", $("k").value);
  const pform = new FormData();
  pform.append("file", file, file.name);
  const rendering = fetch("/web/preview.png", { method: "POST", body: pform })
    .then((r) => (r.ok ? r.blob() : null)).catch(() => null);
  try {
    const response = await api("/search", { method: "POST", body: form });
    const png = await rendering;
    query.thumbnail = png ? URL.createObjectURL(png) : "";
    renderResults(out, query, response);
    $("search-form").classList.add("compact");
  } catch (err) {
    out.replaceChildren();
    showError(`Search failed: ${err.message}`);
  } finally {
    clearInterval(ticker);
  }
}

function setupDropzone() {
  const zone = $("search-form");
  const input = $("file");
  input.addEventListener("change", () => input.files.length && runSearch(input.files[0]));
  zone.addEventListener("click", (event) => {
    if (event.target.closest("select, label, option")) return;
    input.click();
  });
  zone.addEventListener("keydown", (event) => {
    if (event.key === "Enter" || event.key === " ") { event.preventDefault(); input.click(); }
  });
  for (const name of ["dragenter", "dragover"]) {
    zone.addEventListener(name, (event) => { event.preventDefault(); zone.classList.add("over"); });
  }
  for (const name of ["dragleave", "drop"]) {
    zone.addEventListener(name, (event) => { event.preventDefault(); zone.classList.remove("over"); });
  }
  zone.addEventListener("drop", (event) => {
    const file = event.dataTransfer.files[0];
    if (file) runSearch(file);
  });
}

// ---- browse ---------------------------------------------------------------------------------------------
async function loadPage() {
  const params = new URLSearchParams({ offset: state.offset, limit: PAGE_SIZE });
  if (state.label) params.set("label", state.label);
  if (state.status) params.set("status", state.status);
  const grid = $("grid");
  const ticket = ++state.ticket;  // a slower, older answer must not overwrite a newer one
  try {
    const page = await api(`/models?${params}`);
    if (ticket !== state.ticket) return;
    state.count = page.count;
    grid.replaceChildren(...page.data.map(modelCard));
    if (!page.data.length) grid.append(el("p", { class: "empty" }, "No models match."));
    for (const m of page.data) if (m.label) state.labels.add(m.label);
    updateLabelList();
    const last = Math.min(state.offset + page.data.length, page.count);
    $("page-info").textContent = page.count ? `${state.offset + 1}–${last} of ${page.count}` : "0 models";
    $("prev").disabled = state.offset === 0;
    $("next").disabled = last >= page.count;
  } catch (err) {
    showError(`Could not list models: ${err.message}`);
  }
}

function modelCard(m) {
  return el("div", {
    class: "card model", dataset: { modelId: m.id }, tabindex: "0",
    title: m.status === "ready" ? "show similar models" : `status: ${m.status}`,
    onclick: () => showSimilar(m.id),
  },
    thumb(thumbUrl(m.id), m.name, true),
    el("div", { class: "meta" },
      el("div", { class: "name", title: m.name }, m.name),
      el("div", { class: "row" }, labelChip(m.label),
        m.status !== "ready" ? el("span", { class: `badge ${m.status}`, title: m.error || "" }, m.status) : null),
    ),
  );
}

function updateLabelList() {
  const list = $("labels");
  list.replaceChildren(...[...state.labels].sort().map((label) => el("option", { value: label })));
}

async function showSimilar(modelId) {
  clearError();
  selectTab("browse");
  const out = $("similar-results");
  out.replaceChildren(el("div", { class: "loading" }, el("span", { class: "spinner" }), "Searching…"));
  try {
    const [model, response, variants] = await Promise.all([
      api(`/models/${modelId}`),
      api(`/models/${modelId}/similar?k=${$("k").value}`),
      api(`/models/${modelId}/variants`),
    ]);
    const query = { name: model.name, label: model.label, thumbnail: thumbUrl(model.id), modelId: model.id };
    renderResults(out, query, response);
    if (variants.count) out.prepend(renderVariants(out, query, variants));
    const close = el("button", { class: "button ghost", onclick: () => out.replaceChildren() }, "Close");
    out.querySelector(".results-head").append(close);
    out.scrollIntoView({ behavior: "smooth", block: "start" });
  } catch (err) {
    out.replaceChildren();
    showError(`Similar models of #${modelId}: ${err.message}`);
  }
}

// ---- variants: the same model in another form, with the evidence; decisions are recorded, never acted on --
function describeVariant(v) {
  const parts = [`${Math.round(v.confidence * 100)} %`];
  if (v.relation === "rescaled" || Math.abs(Math.log(v.scale)) > 1e-4) parts.push(`× ${v.scale.toPrecision(4)}`);
  if (v.copies > 1) parts.push(`${v.copies} copies`);
  if (!v.same_triangles) parts.push(`chamfer ${(v.chamfer * 100).toFixed(2)} %`);
  return parts.join(" · ");
}

function renderVariants(container, query, variants) {
  const cards = variants.data.map((v) => {
    const status = el("span", { class: "decision" }, v.decision ? v.decision.decision.replace("_", " ") : "");
    const decide = (decision) => async (event) => {
      event.stopPropagation();
      try {
        const r = await api(`/models/${query.modelId}/variants/${v.model_id}/decision`, {
          method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ decision }),
        });
        status.textContent = r.decision.replace("_", " ");
      } catch (err) { showError(`Could not record the decision: ${err.message}`); }
    };
    return el("div", {
      class: "card hit variant", tabindex: "0", dataset: { modelId: v.model_id },
      title: "open both in 3D", onclick: () => openCompare(container, query, v),
    },
      el("div", { class: "rank" }, v.relation.replace("_", " ")),
      thumb(thumbUrl(v.model_id), v.name),
      el("div", { class: "meta" },
        el("div", { class: "name", title: v.name }, v.name),
        el("div", { class: "row" }, el("span", { class: "distance" }, describeVariant(v))),
        el("div", { class: "row" },
          el("button", { class: "similar-link", onclick: decide("keep_both") }, "keep both"),
          el("button", { class: "similar-link", onclick: decide("not_variant") }, "not a variant"),
          status),
      ),
    );
  });
  return el("section", { class: "results variants" },
    el("div", { class: "results-head" }, el("h2", {}, `Variants of “${query.name}”`),
      el("span", { class: "timing" }, "the same model in another form; nothing is deleted or merged")),
    el("div", { class: "hits" }, cards));
}

async function loadLabels() {
  // every label in use, for the filter suggestions
  try {
    const page = await api("/labels");
    for (const item of page.data) state.labels.add(item.label);
    updateLabelList();
  } catch (err) { /* the grid reports errors */ }
}

// ---- tabs, status, wiring ---------------------------------------------------------------------------------
function selectTab(name) {
  for (const tab of document.querySelectorAll(".tab[data-tab]")) {
    tab.classList.toggle("active", tab.dataset.tab === name);
  }
  $("panel-search").hidden = name !== "search";
  $("panel-browse").hidden = name !== "browse";
  if (name === "browse" && !$("grid").childElementCount) loadPage();
  if (location.hash.slice(1).split("/")[0] !== name) history.replaceState(null, "", `#${name}`);
}

async function refreshStatus() {
  const pill = $("status");
  try {
    const response = await fetch("/readyz");
    const body = await response.json();
    const n = body.checks && body.checks.indexed_models;
    pill.textContent = body.ready ? `ready · ${n} indexed` : "not ready";
    pill.className = `status ${body.ready ? "ok" : "warn"}`;
    pill.title = body.ready ? "vocabulary, index, database and workers are up" : (body.checks.hint || JSON.stringify(body.checks));
  } catch (err) {
    pill.textContent = "offline";
    pill.className = "status bad";
  }
}

// #browse, or #similar/<id> (a shareable link to one model's neighbours)
function route() {
  const [name, arg] = location.hash.slice(1).split("/");
  if (name === "similar" && arg) { selectTab("browse"); showSimilar(Number(arg)); }
  else selectTab(name === "browse" ? "browse" : "search");
}

function trackTopbarHeight() {  // style.css's scroll margins clear the sticky bar at its real height
  const bar = document.querySelector(".topbar");
  const update = () => document.documentElement.style.setProperty("--topbar-height", `${bar.offsetHeight}px`);
  update();
  new ResizeObserver(update).observe(bar);
}

function init() {
  trackTopbarHeight();
  for (const tab of document.querySelectorAll(".tab[data-tab]")) {
    tab.addEventListener("click", () => selectTab(tab.dataset.tab));
  }
  $("error-close").addEventListener("click", clearError);
  setupDropzone();
  let typing;
  $("label-filter").addEventListener("input", (event) => {
    clearTimeout(typing);
    typing = setTimeout(() => { state.label = event.target.value.trim(); state.offset = 0; loadPage(); }, 250);
  });
  $("status-filter").addEventListener("change", (event) => { state.status = event.target.value; state.offset = 0; loadPage(); });
  $("prev").addEventListener("click", () => { state.offset = Math.max(0, state.offset - PAGE_SIZE); loadPage(); });
  $("next").addEventListener("click", () => { state.offset += PAGE_SIZE; loadPage(); });

  route();
  window.addEventListener("hashchange", route);  // a link or a typed #similar/<id> on the open page
  loadLabels();
  refreshStatus();
  setInterval(refreshStatus, 15000);
}

document.addEventListener("DOMContentLoaded", init);
