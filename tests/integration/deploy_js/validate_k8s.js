#!/usr/bin/env node
// node validate_k8s.js FILE.yaml...: validates every document of the given Kubernetes manifests
// against the JSON schema of its apiVersion/kind, as typed by the npm package kubernetes-models
// (generated from the Kubernetes OpenAPI spec), and reports fields the schema does not define
// (the API server's strict field validation, `kubectl apply --validate=strict`, rejects those; the
// OpenAPI schemas alone let them through). A kustomization.yaml is not a Kubernetes resource: it
// is skipped, but the files its `resources:` list names must exist.
// Exit status 0 when every document is valid, 1 otherwise (one line per problem on stderr:
// file, document index, kind/name and the message).
"use strict";
const fs = require("node:fs");
const path = require("node:path");
const YAML = require("yaml");

const problems = [];
const report = (where, msg) => problems.push(`${where}: ${msg}`);

// model(apiVersion, kind): the kubernetes-models class, or null. Core "v1" lives in
// kubernetes-models/v1, "group/version" in kubernetes-models/group/version.
function model(apiVersion, kind) {
  if (typeof apiVersion !== "string" || !/^[a-z0-9.-]+(\/v[0-9a-z]+)?$/.test(apiVersion)) return null;
  let mod;
  try {
    mod = require(`kubernetes-models/${apiVersion}`);
  } catch {
    return null;
  }
  const cls = mod[kind];
  return typeof cls === "function" && cls.apiVersion === apiVersion && cls.kind === kind ? cls : null;
}

// validateStrict(instance): runs the model's schema validation on a view of the instance that
// records which properties the validator reads; the generated validators read every property their
// schema defines (and every entry of maps such as labels or ConfigMap data), so a property never
// read is not in the schema. Returns the JSON pointers of such unknown fields.
function validateStrict(instance) {
  const read = new WeakMap(); // object -> Set of property names the validator read
  const proxies = new WeakMap();
  const wrap = (obj) => {
    if (obj === null || typeof obj !== "object") return obj;
    if (proxies.has(obj)) return proxies.get(obj);
    read.set(obj, new Set());
    const p = new Proxy(obj, {
      get(t, k) {
        if (typeof k === "string") read.get(t).add(k);
        return wrap(t[k]);
      },
      has(t, k) {
        if (typeof k === "string") read.get(t).add(k);
        return k in t;
      },
    });
    proxies.set(obj, p);
    return p;
  };
  Object.getPrototypeOf(instance).validate.call(wrap(instance)); // throws a ValidationError
  const unknown = [];
  const walk = (obj, ptr) => {
    if (obj === null || typeof obj !== "object") return;
    const seen = read.get(obj);
    for (const [k, v] of Object.entries(obj)) {
      const here = `${ptr}/${k}`;
      if (!Array.isArray(obj) && seen && !seen.has(k)) unknown.push(here);
      else walk(v, here);
    }
  };
  walk(instance, "");
  return unknown;
}

function checkKustomization(file, docs) {
  const where = `${file} (kustomization, not a Kubernetes resource: skipped)`;
  if (docs.length !== 1 || docs[0].kind !== "Kustomization") {
    report(where, "expected one document of kind Kustomization");
    return;
  }
  const res = docs[0].resources;
  if (!Array.isArray(res) || res.length === 0) {
    report(where, "no resources: list");
    return;
  }
  for (const r of res) {
    if (typeof r !== "string" || !fs.statSync(path.resolve(path.dirname(file), r), { throwIfNoEntry: false })?.isFile())
      report(where, `resources: names ${JSON.stringify(r)}, which is not a file next to it`);
  }
}

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error("usage: node validate_k8s.js FILE.yaml...");
  process.exit(2);
}
let validated = 0;
for (const file of files) {
  let src;
  try {
    src = fs.readFileSync(file, "utf8");
  } catch (e) {
    report(file, e.message);
    continue;
  }
  const parsed = YAML.parseAllDocuments(src, { prettyErrors: true });
  const docs = [];
  parsed.forEach((d, i) => {
    for (const e of [...d.errors, ...d.warnings]) report(`${file} document ${i}`, `YAML: ${e.message}`);
    docs.push(d.toJS());
  });
  if (path.basename(file) === "kustomization.yaml") {
    checkKustomization(file, docs);
    continue;
  }
  docs.forEach((obj, i) => {
    if (obj === null || obj === undefined) return; // an empty document (e.g. a trailing ---)
    const name = obj?.metadata?.name;
    const where = `${file} document ${i} (${obj?.kind ?? "no kind"}/${name ?? "no name"})`;
    if (typeof obj !== "object" || Array.isArray(obj)) return report(where, "not a mapping");
    const Model = model(obj.apiVersion, obj.kind);
    if (!Model) return report(where, `no schema for apiVersion ${obj.apiVersion}, kind ${obj.kind}`);
    if (typeof name !== "string" || name === "") report(where, "metadata.name missing");
    let unknown;
    try {
      unknown = validateStrict(new Model(obj));
    } catch (e) {
      return report(where, `${obj.apiVersion} ${obj.kind} schema: ${e.message}`);
    }
    for (const u of unknown) report(where, `${obj.apiVersion} ${obj.kind} schema: unknown field ${u}`);
    validated++;
  });
}
for (const p of problems) console.error(`validate_k8s: ${p}`);
if (problems.length) process.exit(1);
console.log(`validate_k8s: ${validated} objects valid (kubernetes-models ${require("kubernetes-models/package.json").version})`);
