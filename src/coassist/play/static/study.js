// coassist study: the participant's side of a study on the play page. The server decides what comes next
// (a trial, a questionnaire, a rest); this page shows it, under a label (A, B, C…) only, and sends back
// the Start, the answers and the "go on". Inactive on a plain `coassist play` page (no "study" in init).
"use strict";
(() => {
  const api = window.coassist;
  const $ = (id) => document.getElementById(id);
  api.study = null;

  function show(view) {
    api.study = view;
    $("study").hidden = false;
    $("controller").parentElement.hidden = true;
    $("explain").hidden = true;
    const title = view.kind === "done" ? "Done" : `Step ${view.step + 1} of ${view.of}`;
    $("study-title").textContent = title + (view.label ? ` — condition ${view.label}` : "");
    $("study-text").textContent = view.text || "";
    const form = $("study-form"), next = $("study-next");
    form.hidden = view.kind !== "questionnaire"; next.hidden = view.kind !== "rest";
    api.startName = view.kind === "trial" ? (view.label || "go") : null;
    $("start").disabled = view.kind !== "trial" || api.running || api.role !== "hand";
    if (view.kind === "trial" && view.scene) { api.scene = view.scene; api.frame = null; }
    if (view.kind === "questionnaire") renderForm(view);
    if (view.kind === "rest") rest(view);
  }

  function renderForm(view) {
    const form = $("study-form");
    // The same questionnaire shown again (a reconnect's init, a repeated step) keeps what was already
    // entered: a participant's answers are never wiped under their cursor.
    const kept = new Map();
    if (form.dataset.step === String(view.step)) {
      for (const el of form.querySelectorAll("input")) {
        if (el.type === "range" || el.checked) kept.set(el.name, el.value);
      }
    }
    form.innerHTML = ""; form.dataset.step = String(view.step);
    view.form.items.forEach((it, i) => {
      const div = document.createElement("div"); div.className = "item";
      const label = document.createElement("label"); label.textContent = it.text; div.appendChild(label);
      if (it.scale === "tlx") {
        const input = document.createElement("input");
        Object.assign(input, { type: "range", min: it.lo, max: it.hi, step: it.step, value: Math.round((it.lo + it.hi) / 2 / it.step) * it.step, name: it.key, id: `q-${i}` });
        const ends = document.createElement("div"); ends.className = "ends";
        ends.innerHTML = it.key === "tlx_performance" ? "<span>perfect</span><span>failure</span>" : "<span>very low</span><span>very high</span>";
        if (kept.has(it.key)) input.value = kept.get(it.key);
        div.appendChild(input); div.appendChild(ends);
      } else {
        const scale = document.createElement("div"); scale.className = "scale";
        scale.appendChild(document.createTextNode("disagree"));
        for (let v = it.lo; v <= it.hi; v += it.step) {
          const r = document.createElement("input"); Object.assign(r, { type: "radio", name: it.key, value: v, id: `q-${i}-${v}` });
          r.checked = kept.get(it.key) === String(v);
          scale.appendChild(r);
        }
        scale.appendChild(document.createTextNode("agree"));
        div.appendChild(scale);
      }
      form.appendChild(div);
    });
    const submit = document.createElement("button"); submit.type = "submit"; submit.id = "study-submit"; submit.textContent = "Send answers";
    form.appendChild(submit);
    form.onsubmit = (ev) => {
      ev.preventDefault();
      const values = [];
      for (const it of view.form.items) {
        const el = it.scale === "tlx" ? form.querySelector(`input[name="${it.key}"]`) : form.querySelector(`input[name="${it.key}"]:checked`);
        if (!el) { $("study-text").textContent = "Please answer every statement."; return; }
        values.push(Number(el.value));
      }
      api.send({ type: "answers", step: view.step, values });
    };
  }

  let timer = null;
  function rest(view) {
    const next = $("study-next");
    next.disabled = !view.ready;
    next.onclick = () => api.send({ type: "next", step: view.step });
    if (timer) clearInterval(timer);
    const end = performance.now() + 1000 * (view.seconds || 0);
    const tick = () => {
      const left = Math.max(0, Math.ceil((end - performance.now()) / 1000));
      $("study-text").textContent = `${view.text} ${left > 0 ? `(${left} s)` : view.ready ? "" : "(the robot is still learning…)"}`;
    };
    tick(); timer = setInterval(tick, 500);
  }

  api.extend = (m) => {
    if (m.type === "init" && m.study) show(m.study);
    else if (m.type === "step") show(m);
    else if (api.study && m.type === "result") {  // the trial is done: nothing to start until the next step comes
      api.study = Object.assign({}, api.study, { kind: "wait" }); api.startName = null; $("start").disabled = true;
    } else if (api.study && (m.type === "started" || m.type === "status")) {
      $("start").disabled = api.study.kind !== "trial" || api.running || api.role !== "hand";
    }
  };
})();
