#!/usr/bin/env node
// node job_rules.js FILE.yaml...: the rules the Kubernetes API server enforces on a Job (and on the
// names of Pods and their containers) beyond what the OpenAPI schema can express — validate_k8s.js
// checks the schema. Each rule names where it comes from (docs/DEPLOY.md §9 has the same table):
// the Job validation of the API server, pkg/apis/batch/validation/validation.go (ValidateJob,
// validateJobSpec, validatePodFailurePolicy*), and the object-meta, label and container checks of
// k8s.io/apimachinery and pkg/apis/core/validation, as of Kubernetes 1.33 (the schemas' version).
// Exit status 0 when every object keeps every rule, 1 otherwise: one line per breach on stderr,
// `job_rules: FILE document I (Kind/name): rule ID: message`. `node job_rules.js --list` prints the
// rule ids, one a line (the tests break each one).
"use strict";
const fs = require("node:fs");
const YAML = require("yaml");

const DNS1123_LABEL = /^[a-z0-9]([-a-z0-9]*[a-z0-9])?$/;
const DNS1123_SUBDOMAIN = /^[a-z0-9]([-a-z0-9]*[a-z0-9])?(\.[a-z0-9]([-a-z0-9]*[a-z0-9])?)*$/;
const LABEL_VALUE = /^(([A-Za-z0-9][-A-Za-z0-9_.]*)?[A-Za-z0-9])?$/;
const isLabel = (s) => typeof s === "string" && s.length <= 63 && DNS1123_LABEL.test(s);
const has = (o, k) => o !== null && typeof o === "object" && o[k] !== undefined && o[k] !== null;

// Each rule: id, source, check(obj, report) where report(message) records a breach.
const RULES = [
  {
    id: "name-dns-subdomain",
    kinds: ["Job", "Pod", "PersistentVolumeClaim"],
    source: "ValidateObjectMeta with NameIsDNSSubdomain (apimachinery)",
    check(o, bad) {
      const n = o.metadata?.name;
      if (typeof n !== "string" || n.length > 253 || !DNS1123_SUBDOMAIN.test(n))
        bad(`metadata.name ${JSON.stringify(n)} is not a DNS-1123 subdomain (lower case, digits, '-', '.'; at most 253)`);
    },
  },
  {
    id: "job-name-label",
    kinds: ["Job"],
    source: "the Job's pods are labelled job-name and batch.kubernetes.io/job-name = its name; a label value is at most 63 characters (pkg/registry/batch/job/strategy.go, IsValidLabelValue)",
    check(o, bad) {
      const n = o.metadata?.name;
      if (typeof n === "string" && (n.length > 63 || !LABEL_VALUE.test(n)))
        bad(`Job name ${n} (${n.length} characters) is not a valid label value (at most 63)`);
    },
  },
  {
    id: "indexed-pod-hostname",
    kinds: ["Job"],
    source: "ValidateJob: an Indexed Job's pod hostname NAME-(completions-1) must be a DNS-1123 label",
    check(o, bad) {
      const s = o.spec ?? {};
      if (s.completionMode === "Indexed" && Number.isInteger(s.completions) && s.completions > 0) {
        const h = `${o.metadata?.name}-${s.completions - 1}`;
        if (!isLabel(h)) bad(`the last pod hostname ${h} (${h.length} characters) is not a DNS-1123 label (at most 63)`);
      }
    },
  },
  {
    id: "nonnegative",
    kinds: ["Job"],
    source: "validateJobSpec: ValidateNonnegativeField",
    check(o, bad) {
      for (const k of ["parallelism", "completions", "activeDeadlineSeconds", "backoffLimit",
        "ttlSecondsAfterFinished", "backoffLimitPerIndex", "maxFailedIndexes"])
        if (has(o.spec, k) && o.spec[k] < 0) bad(`spec.${k} ${o.spec[k]} is negative`);
    },
  },
  {
    id: "restart-policy",
    kinds: ["Job"],
    source: "validateJobSpec: restartPolicy OnFailure or Never (Always, the pod default, is refused)",
    check(o, bad) {
      const r = o.spec?.template?.spec?.restartPolicy;
      if (r !== "OnFailure" && r !== "Never") bad(`restartPolicy ${r ?? "(unset: Always)"}: OnFailure or Never`);
    },
  },
  {
    id: "podFailurePolicy-restartPolicy-never",
    kinds: ["Job"],
    source: "validateJobSpec: only Never is supported when podFailurePolicy is specified",
    check(o, bad) {
      if (has(o.spec, "podFailurePolicy") && o.spec.template?.spec?.restartPolicy !== "Never")
        bad(`podFailurePolicy with restartPolicy ${o.spec.template?.spec?.restartPolicy}: needs Never`);
    },
  },
  {
    id: "FailIndex-needs-backoffLimitPerIndex",
    kinds: ["Job"],
    source: "validatePodFailurePolicyRule: FailIndex requires the backoffLimitPerIndex to be set",
    check(o, bad) {
      const rules = o.spec?.podFailurePolicy?.rules ?? [];
      if (rules.some((r) => r?.action === "FailIndex") && !has(o.spec, "backoffLimitPerIndex"))
        bad("a podFailurePolicy rule FailIndex without backoffLimitPerIndex");
    },
  },
  {
    id: "per-index-needs-Indexed",
    kinds: ["Job"],
    source: "validateJobSpec: backoffLimitPerIndex and maxFailedIndexes require indexed completion mode",
    check(o, bad) {
      for (const k of ["backoffLimitPerIndex", "maxFailedIndexes"])
        if (has(o.spec, k) && o.spec.completionMode !== "Indexed")
          bad(`spec.${k} with completionMode ${o.spec.completionMode ?? "NonIndexed"}: requires Indexed`);
    },
  },
  {
    id: "maxFailedIndexes-needs-backoffLimitPerIndex",
    kinds: ["Job"],
    source: "validateJobSpec: backoffLimitPerIndex required when maxFailedIndexes is specified",
    check(o, bad) {
      if (has(o.spec, "maxFailedIndexes") && !has(o.spec, "backoffLimitPerIndex"))
        bad("spec.maxFailedIndexes without spec.backoffLimitPerIndex");
    },
  },
  {
    id: "Indexed-needs-completions",
    kinds: ["Job"],
    source: "validateJobSpec: completions required when completion mode is Indexed",
    check(o, bad) {
      if (o.spec?.completionMode === "Indexed" && !has(o.spec, "completions"))
        bad("completionMode Indexed without spec.completions");
    },
  },
  {
    id: "maxFailedIndexes<=completions",
    kinds: ["Job"],
    source: "validateJobSpec (Indexed): maxFailedIndexes must be less than or equal to completions",
    check(o, bad) {
      const s = o.spec ?? {};
      if (s.completionMode === "Indexed" && has(s, "completions") && has(s, "maxFailedIndexes") &&
        s.maxFailedIndexes > s.completions)
        bad(`spec.maxFailedIndexes ${s.maxFailedIndexes} > spec.completions ${s.completions}`);
    },
  },
  {
    id: "Indexed-parallelism<=100000",
    kinds: ["Job"],
    source: "validateJobSpec: maxParallelismForIndexedJob = 100000",
    check(o, bad) {
      const s = o.spec ?? {};
      if (s.completionMode === "Indexed" && has(s, "parallelism") && s.parallelism > 100000)
        bad(`spec.parallelism ${s.parallelism} > 100000 in an Indexed Job`);
    },
  },
  {
    id: "maxFailedIndexes<=100000",
    kinds: ["Job"],
    source: "validateJobSpec: maxFailedIndexesForIndexedJob = 100000",
    check(o, bad) {
      if (has(o.spec, "maxFailedIndexes") && o.spec.maxFailedIndexes > 100000)
        bad(`spec.maxFailedIndexes ${o.spec.maxFailedIndexes} > 100000`);
    },
  },
  {
    id: "completions>100000-limits",
    kinds: ["Job"],
    source: "validateJobSpec: completions above completionsSoftLimit 100000 with backoffLimitPerIndex need maxFailedIndexes <= 10000 and parallelism <= 10000",
    check(o, bad) {
      const s = o.spec ?? {};
      if (s.completionMode !== "Indexed" || !(s.completions > 100000) || !has(s, "backoffLimitPerIndex")) return;
      if (!has(s, "maxFailedIndexes")) bad(`completions ${s.completions} > 100000: maxFailedIndexes must be set`);
      else if (s.maxFailedIndexes > 10000) bad(`completions ${s.completions} > 100000: maxFailedIndexes ${s.maxFailedIndexes} > 10000`);
      if (has(s, "parallelism") && s.parallelism > 10000)
        bad(`completions ${s.completions} > 100000: parallelism ${s.parallelism} > 10000`);
    },
  },
  {
    id: "podFailurePolicy-rules",
    kinds: ["Job"],
    source: "validatePodFailurePolicy*: at most 20 rules, each onExitCodes or onPodConditions (one of them), onExitCodes.containerName one of the pod's containers, 1..255 values, ordered, unique, no 0 with In",
    check(o, bad) {
      const rules = o.spec?.podFailurePolicy?.rules;
      if (!Array.isArray(rules)) return;
      if (rules.length > 20) bad(`${rules.length} podFailurePolicy rules, at most 20`);
      const names = new Set([...(o.spec.template?.spec?.containers ?? []), ...(o.spec.template?.spec?.initContainers ?? [])].map((c) => c?.name));
      rules.forEach((r, i) => {
        const exit = r?.onExitCodes, cond = r?.onPodConditions;
        const hasCond = Array.isArray(cond) && cond.length > 0;
        if (!!exit === hasCond) bad(`podFailurePolicy rule ${i}: exactly one of onExitCodes and onPodConditions`);
        if (!exit) return;
        if (has(exit, "containerName") && !names.has(exit.containerName))
          bad(`podFailurePolicy rule ${i}: containerName ${exit.containerName} is not a container of the pod`);
        const v = exit.values ?? [];
        if (v.length === 0 || v.length > 255) bad(`podFailurePolicy rule ${i}: ${v.length} exit codes (1 to 255)`);
        if (exit.operator === "In" && v.includes(0)) bad(`podFailurePolicy rule ${i}: exit code 0 with operator In`);
        if (new Set(v).size !== v.length) bad(`podFailurePolicy rule ${i}: duplicate exit codes`);
        if (v.some((x, j) => j > 0 && v[j - 1] > x)) bad(`podFailurePolicy rule ${i}: exit codes must be ordered`);
      });
    },
  },
  {
    id: "podReplacementPolicy-with-podFailurePolicy",
    kinds: ["Job"],
    source: "validatePodReplacementPolicy: only Failed when podFailurePolicy is specified",
    check(o, bad) {
      const p = o.spec?.podReplacementPolicy;
      if (p !== undefined && has(o.spec, "podFailurePolicy") && p !== "Failed")
        bad(`podReplacementPolicy ${p} with a podFailurePolicy: only Failed`);
    },
  },
  {
    id: "container-names",
    kinds: ["Job", "Pod"],
    source: "pkg/apis/core/validation validateContainers: each name a DNS-1123 label, unique in the pod",
    check(o, bad) {
      const pod = o.kind === "Pod" ? o.spec : o.spec?.template?.spec;
      const cs = [...(pod?.containers ?? []), ...(pod?.initContainers ?? [])];
      const seen = new Set();
      for (const c of cs) {
        if (!isLabel(c?.name)) bad(`container name ${JSON.stringify(c?.name)} is not a DNS-1123 label`);
        if (seen.has(c?.name)) bad(`container name ${c?.name} twice`);
        seen.add(c?.name);
      }
    },
  },
];

const args = process.argv.slice(2);
if (args[0] === "--list") {
  for (const r of RULES) console.log(`${r.id}\t${r.source}`);
  process.exit(0);
}
if (args.length === 0) {
  console.error("usage: node job_rules.js FILE.yaml... | --list");
  process.exit(2);
}
const problems = [];
let checked = 0;
for (const file of args) {
  let docs;
  try {
    docs = YAML.parseAllDocuments(fs.readFileSync(file, "utf8")).map((d) => d.toJS());
  } catch (e) {
    problems.push(`${file}: ${e.message}`);
    continue;
  }
  docs.forEach((o, i) => {
    if (o === null || typeof o !== "object") return;
    const where = `${file} document ${i} (${o.kind}/${o.metadata?.name})`;
    const rules = RULES.filter((r) => r.kinds.includes(o.kind));
    if (rules.length) checked++;
    for (const r of rules) r.check(o, (msg) => problems.push(`${where}: rule ${r.id}: ${msg}`));
  });
}
for (const p of problems) console.error(`job_rules: ${p}`);
if (problems.length) process.exit(1);
console.log(`job_rules: ${checked} objects keep the ${RULES.length} rules`);
