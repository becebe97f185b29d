// Offline validation of the Kubernetes manifests in docker/k8s (no cluster, no API server):
//
//  1. every object against its Kubernetes OpenAPI schema (kubernetes-models' validate());
//  2. strict fields: the schemas accept any unknown field (a typo such as `readinesProbe` would
//     pass, and the API server would drop it or refuse it), so every field is also looked up in
//     the models' type declarations (.d.ts), which list each object's fields;
//  3. how the objects fit together and fit the server: selectors match the pod labels, Services
//     and probes name container ports, probes ask for cloudcast.v1.CloudCast, the server listens
//     on loopback behind the HAProxy container (whose ConfigMap holds docker/haproxy's files,
//     byte for byte), the HPA targets the Deployment, the NetworkPolicy admits exactly the gRPC
//     and metrics ports, the grace period covers preStop plus the server's shutdown-grace and the
//     proxy outlives the drain, the kustomization lists every manifest;
//  4. with --server BIN: the ConfigMap's config names only flags the server has, and the
//     server starts with the Deployment's args and that config, then drains on SIGTERM;
//  5. that the checks can fail: broken copies of the Deployment (made in memory) must be refused.
//
//   node validate.js MANIFEST_DIR [--server PATH/cloudcast-server]
//
// Prints one line per object and check, then "N passed, N failed"; exits 1 on any failure.
"use strict";

const fs = require("fs");
const os = require("os");
const path = require("path");
const childProcess = require("child_process");
const yaml = require("js-yaml");

const kHealthService = "cloudcast.v1.CloudCast";
const kPorts = { grpc: 50051, metrics: 9464 };

let passed = 0;
let failed = 0;
function check(ok, what, detail) {
  if (ok) {
    passed++;
    console.log(`ok    ${what}`);
  } else {
    failed++;
    console.log(`FAIL  ${what}${detail ? ": " + detail : ""}`);
  }
  return ok;
}

// --- schemas --------------------------------------------------------------------------------

const modelsDir = path.dirname(require.resolve("kubernetes-models/package.json"));
const nodeModules = path.dirname(modelsDir);

// "apps/v1" -> kubernetes-models/apps/v1; the core group "v1" -> kubernetes-models/v1.
function modelDir(apiVersion) {
  const dir = path.join(modelsDir, apiVersion);
  return fs.existsSync(path.join(dir, "index.js")) ? dir : null;
}

function modelClass(obj) {
  const dir = modelDir(String(obj.apiVersion));
  if (dir === null) return null;
  const file = path.join(dir, `${obj.kind}.js`);
  if (!fs.existsSync(file)) return null;
  return require(file)[obj.kind] || null;
}

// Schema errors of `obj` ("" when valid).
function schemaErrors(obj) {
  const Model = modelClass(obj);
  if (Model === null) return `no Kubernetes model for apiVersion ${obj.apiVersion} kind ${obj.kind}`;
  try {
    new Model(obj).validate();
    return "";
  } catch (e) {
    return String(e.message || e).split("\n").slice(0, 6).join("; ");
  }
}

// --- strict fields, from the models' type declarations ----------------------------------------

// One .d.ts: the fields of its model's interface and, for each, the .d.ts of its type when that
// type is another model (directly or as an array's element).
const declarations = new Map();
function declaration(file) {
  if (declarations.has(file)) return declarations.get(file);
  const text = fs.readFileSync(file, "utf8");
  const imports = new Map();
  for (const m of text.matchAll(/^import \{ (\w+) \} from "([^"]+)";$/gm)) imports.set(m[1], m[2]);
  const body = /^export interface \w+(?: extends [\w, ]+)? \{\n([\s\S]*?)^\}/m.exec(text);
  const fields = new Map();
  if (body) {
    for (const m of body[1].matchAll(/^ {4}"([^"]+)"\??: (.*);?$/gm)) {
      const type = m[2].replace(/;$/, "");
      const named = /^(?:Array<)?(I\w+)>?$/.exec(type);
      let target = null;
      if (named && imports.has(named[1])) {
        const from = imports.get(named[1]);
        target = from.startsWith(".")
          ? path.resolve(path.dirname(file), from + ".d.ts")
          : path.join(nodeModules, from + ".d.ts");
      }
      fields.set(m[1], target);
    }
  }
  const d = { fields, open: !body || /^ {4}\[key: string\]/m.test(body[1]) };
  declarations.set(file, d);
  return d;
}

// Fields of `value` its model does not have, as paths ("spec.template.spec.containers[0].x").
function unknownFields(value, file, where, out) {
  if (value === null || typeof value !== "object") return out;
  if (Array.isArray(value)) {
    value.forEach((v, i) => unknownFields(v, file, `${where}[${i}]`, out));
    return out;
  }
  const d = declaration(file);
  if (d.open) return out;
  for (const [key, v] of Object.entries(value)) {
    if (!d.fields.has(key)) {
      out.push(`${where}${where ? "." : ""}${key}`);
    } else if (d.fields.get(key) !== null) {
      unknownFields(v, d.fields.get(key), `${where}${where ? "." : ""}${key}`, out);
    }
  }
  return out;
}

function strictErrors(obj) {
  const dir = modelDir(String(obj.apiVersion));
  const file = dir && path.join(dir, `${obj.kind}.d.ts`);
  if (!file || !fs.existsSync(file)) return `no type declaration for ${obj.apiVersion} ${obj.kind}`;
  const unknown = unknownFields(obj, file, "", []);
  return unknown.length ? `unknown fields: ${unknown.join(", ")}` : "";
}

function objectErrors(obj) {
  return [schemaErrors(obj), strictErrors(obj)].filter((e) => e !== "").join("; ");
}

// --- how the objects fit together ---------------------------------------------------------------

function matches(selector, labels) {
  const wanted = selector || {};
  return (
    Object.keys(wanted).length > 0 &&
    Object.entries(wanted).every(([k, v]) => labels && labels[k] === v)
  );
}

function seconds(value) {
  return Number(value);
}

// The ConfigMap's server.toml as { key: value } (one `name = value` per line, # comments).
function parseServerConfig(text) {
  const config = {};
  for (const raw of text.split("\n")) {
    const line = raw.replace(/#.*/, "").trim();
    if (!line) continue;
    const m = /^([\w-]+)\s*=\s*(.*)$/.exec(line);
    if (!m) {
      config[`(unparsable line: ${raw.trim()})`] = "";
      continue;
    }
    config[m[1]] = m[2].replace(/^"(.*)"$/, "$1");
  }
  return config;
}

// The Pod: the server, and HAProxy in front of it (the `proxy` container). Clients reach the
// proxy's port; the server listens on loopback only.
const kServerListen = "127.0.0.1:50052";

function crossChecks(objects, dir) {
  const byKind = (kind) => objects.filter((o) => o.kind === kind);
  const [deployment] = byKind("Deployment");
  if (!check(deployment !== undefined, "a Deployment exists")) return;
  const pod = deployment.spec.template;
  const labels = pod.metadata.labels;
  const containers = pod.spec.containers;
  const container = containers.find((c) => c.name === "server");
  const proxy = containers.find((c) => c.name === "proxy");
  if (!check(container !== undefined && proxy !== undefined, "the Pod has a server and a proxy container")) return;
  check(containers[0] === container, "the server is the Pod's first container (kube-play.js, smoke.sh)");
  // Ports are the Pod's: the proxy's grpc, the server's metrics.
  const ports = new Map(containers.flatMap((c) => (c.ports || []).map((p) => [p.name, p.containerPort])));
  check(
    ports.get("grpc") === kPorts.grpc && ports.get("metrics") === kPorts.metrics && ports.size === 2,
    `Pod ports grpc ${kPorts.grpc} and metrics ${kPorts.metrics}, and no others`,
    JSON.stringify([...ports]),
  );
  check(
    (proxy.ports || []).some((p) => p.name === "grpc") && (container.ports || []).some((p) => p.name === "metrics"),
    "grpc is the proxy's port, metrics the server's",
  );
  check(
    matches(deployment.spec.selector.matchLabels, labels),
    "Deployment selector matches its pod labels",
  );
  const readiness = proxy.readinessProbe;
  check(
    readiness && readiness.grpc && readiness.grpc.port === kPorts.grpc && readiness.grpc.service === kHealthService,
    `the proxy's readinessProbe is a grpc probe of ${kHealthService} on ${kPorts.grpc} (through the proxy to the server)`,
    JSON.stringify(readiness),
  );
  const liveness = container.livenessProbe;
  const live = (liveness && liveness.exec && liveness.exec.command) || [];
  check(
    live[0] === "cloudcast-load" && live.includes("--probe") && live[live.indexOf("--server") + 1] === kServerListen,
    `the server's livenessProbe checks its own health on ${kServerListen}`,
    JSON.stringify(liveness),
  );
  check(
    proxy.livenessProbe && proxy.livenessProbe.tcpSocket && proxy.livenessProbe.tcpSocket.port === kPorts.grpc,
    "the proxy's livenessProbe is its port",
  );
  for (const c of containers) {
    const r = c.resources || {};
    check(
      r.requests && r.requests.cpu && r.requests.memory && r.limits && r.limits.memory,
      `container ${c.name} requests CPU and memory (the HPA needs the CPU requests) and limits memory`,
    );
    const sc = c.securityContext || {};
    check(
      sc.readOnlyRootFilesystem === true && sc.allowPrivilegeEscalation === false,
      `container ${c.name}: read-only root filesystem, no privilege escalation`,
    );
  }
  const args = container.args || [];
  const arg = (flag) => (args.indexOf(flag) >= 0 ? args[args.indexOf(flag) + 1] : undefined);
  check(
    arg("--instance") === "$(POD_NAME)" &&
      (container.env || []).some(
        (e) => e.name === "POD_NAME" && e.valueFrom && e.valueFrom.fieldRef.fieldPath === "metadata.name",
      ),
    "--instance is the pod's name (downward API)",
  );
  check(arg("--listen") === kServerListen, `--listen ${kServerListen} (loopback: only the proxy reaches it)`, arg("--listen"));
  check(arg("--trusted-proxy") === "127.0.0.1", "--trusted-proxy 127.0.0.1 (the proxy names the clients)", arg("--trusted-proxy"));
  check(
    [`0.0.0.0:${kPorts.metrics}`, `:${kPorts.metrics}`].includes(arg("--metrics-listen")),
    "--metrics-listen on 9464",
    arg("--metrics-listen"),
  );

  // The proxy: the shipped configuration, from its ConfigMap, in front of the server's address.
  const env = new Map((proxy.env || []).map((e) => [e.name, e.value]));
  check(env.get("CLOUDCAST_BACKEND") === kServerListen, "the proxy's backend is the server's --listen", env.get("CLOUDCAST_BACKEND"));
  check(env.get("CLOUDCAST_PROXY_LISTEN") === `:${kPorts.grpc}`, `the proxy listens on :${kPorts.grpc}`, env.get("CLOUDCAST_PROXY_LISTEN"));
  const command = proxy.command || [];
  const files = command.filter((_, i) => i > 0 && command[i - 1] === "-f");
  const proxyMount = (proxy.volumeMounts || []).find((m) => files.length && files.every((f) => f.startsWith(m.mountPath + "/")));
  const proxyVolume = proxyMount && pod.spec.volumes.find((v) => v.name === proxyMount.name);
  const proxyConfig = proxyVolume && proxyVolume.configMap && byKind("ConfigMap").find((c) => c.metadata.name === proxyVolume.configMap.name);
  if (check(proxyConfig !== undefined && files.length === 2, "the proxy reads two files of a ConfigMap in these manifests", JSON.stringify(command))) {
    for (const f of files) {
      const key = path.relative(proxyMount.mountPath, f);
      const shipped = path.join(dir, "..", "haproxy", key);
      check(
        fs.existsSync(shipped) && proxyConfig.data[key] === fs.readFileSync(shipped, "utf8"),
        `the ConfigMap's ${key} is docker/haproxy/${key}, byte for byte`,
      );
    }
  }

  // The config: mounted from the ConfigMap, and a grace period that covers the drain.
  const mount = (container.volumeMounts || []).find((m) => arg("--config").startsWith(m.mountPath + "/"));
  const volume = mount && pod.spec.volumes.find((v) => v.name === mount.name);
  const configMap = volume && volume.configMap && byKind("ConfigMap").find((c) => c.metadata.name === volume.configMap.name);
  const configKey = arg("--config") && mount && path.relative(mount.mountPath, arg("--config"));
  const configText = configMap && configMap.data && configMap.data[configKey];
  if (check(typeof configText === "string", "--config is a file of a ConfigMap in these manifests")) {
    const config = parseServerConfig(configText);
    const pauseOf = (c) => {
      const preStop = ((c.lifecycle || {}).preStop || {}).exec;
      return preStop && preStop.command[0] === "sleep" ? seconds(preStop.command[1]) : 0;
    };
    const pause = pauseOf(container);
    const grace = seconds(config["shutdown-grace"] || 5);
    check(
      pod.spec.terminationGracePeriodSeconds > pause + grace,
      `terminationGracePeriodSeconds (${pod.spec.terminationGracePeriodSeconds}) > preStop ${pause} s + shutdown-grace ${grace} s`,
    );
    const proxyPause = pauseOf(proxy);
    check(
      proxyPause >= pause + grace && proxyPause < pod.spec.terminationGracePeriodSeconds,
      `the proxy's preStop (${proxyPause} s) outlives the server's drain (${pause + grace} s) within the grace period`,
    );
    check(
      liveness.periodSeconds * liveness.failureThreshold > pause + grace,
      "the liveness probe cannot fire during a drain (NOT_SERVING until the process exits)",
    );
    check(seconds(config["max-connection-age"]) > 0, "max-connection-age is set (long streams rebalance)");
  }

  for (const service of byKind("Service")) {
    const name = service.metadata.name;
    check(matches(service.spec.selector, labels), `Service ${name} selects the pods`);
    for (const p of service.spec.ports) {
      check(
        ports.has(p.targetPort) || [...ports.values()].includes(p.targetPort),
        `Service ${name} port ${p.name} targets a container port`,
        String(p.targetPort),
      );
    }
  }
  check(
    byKind("Service").some((s) => s.spec.clusterIP === "None" && s.metadata.name === "cloudcast-headless"),
    "a headless Service cloudcast-headless (client-side balancing)",
  );
  check(
    byKind("Service").some((s) => s.spec.clusterIP !== "None" && (s.spec.type || "ClusterIP") === "ClusterIP"),
    "a ClusterIP Service (the L7 path)",
  );
  for (const pdb of byKind("PodDisruptionBudget")) {
    check(matches(pdb.spec.selector.matchLabels, labels), "PodDisruptionBudget selects the pods");
  }
  for (const hpa of byKind("HorizontalPodAutoscaler")) {
    const t = hpa.spec.scaleTargetRef;
    check(
      t.kind === "Deployment" && t.name === deployment.metadata.name,
      "HorizontalPodAutoscaler scales the Deployment",
    );
    check(
      hpa.spec.metrics.some((m) => m.type === "Resource" && m.resource.name === "cpu"),
      "HorizontalPodAutoscaler scales on CPU",
    );
  }
  const [policy] = byKind("NetworkPolicy");
  if (check(policy !== undefined, "a NetworkPolicy exists")) {
    check(matches(policy.spec.podSelector.matchLabels, labels), "NetworkPolicy selects the pods");
    const admitted = new Set();
    for (const rule of policy.spec.ingress || []) {
      for (const p of rule.ports || []) admitted.add(typeof p.port === "string" ? ports.get(p.port) : p.port);
      check((rule.ports || []).length > 0, "every NetworkPolicy ingress rule names its ports");
    }
    check(
      (policy.spec.policyTypes || []).includes("Ingress") &&
        admitted.size === 2 && admitted.has(kPorts.grpc) && admitted.has(kPorts.metrics),
      "NetworkPolicy admits only the gRPC and metrics ports",
      JSON.stringify([...admitted]),
    );
  }
}

// --- the kustomization ----------------------------------------------------------------------

function checkKustomization(dir, manifestFiles) {
  const file = path.join(dir, "kustomization.yaml");
  if (!fs.existsSync(file)) return;
  const k = yaml.load(fs.readFileSync(file, "utf8"));
  const known = new Set(["apiVersion", "kind", "resources", "images", "labels", "namespace", "namePrefix", "nameSuffix", "patches", "configMapGenerator"]);
  check(
    k.apiVersion === "kustomize.config.k8s.io/v1beta1" && k.kind === "Kustomization",
    "kustomization.yaml is a Kustomization",
  );
  const extra = Object.keys(k).filter((key) => !known.has(key));
  check(extra.length === 0, "kustomization.yaml has only known fields", extra.join(", "));
  const listed = new Set(k.resources || []);
  const missing = manifestFiles.filter((f) => !listed.has(f));
  const absent = [...listed].filter((f) => !manifestFiles.includes(f));
  check(missing.length === 0 && absent.length === 0, "kustomization.yaml lists every manifest, and only those",
    `not listed: ${missing.join(", ")}; listed but absent: ${absent.join(", ")}`);
}

// --- the server itself ------------------------------------------------------------------------

function checkWithServer(server, objects) {
  const deployment = objects.find((o) => o.kind === "Deployment");
  const container = deployment.spec.template.spec.containers[0];
  const args = container.args.slice();
  const configPath = args[args.indexOf("--config") + 1];
  const configMap = objects.find((o) => o.kind === "ConfigMap" && o.data && o.data[path.basename(configPath)] !== undefined);
  const text = configMap.data[path.basename(configPath)];

  // The server takes unknown keys in --config without a word, so they are checked here.
  const help = childProcess.spawnSync(server, ["--help"], { encoding: "utf8", timeout: 20000 });
  const flags = new Set([...String(help.stdout).matchAll(/--([a-z][a-z0-9-]*)/g)].map((m) => m[1]));
  check(flags.has("shutdown-grace"), "cloudcast-server --help lists its flags");
  const unknown = Object.keys(parseServerConfig(text)).filter((key) => !flags.has(key));
  check(unknown.length === 0, "every key of the ConfigMap's config is a cloudcast-server flag", unknown.join(", "));

  // Starts with the Deployment's args: listen addresses on loopback, port 0, the config from a
  // scratch file; it must say it listens, then drain on SIGTERM and exit 0.
  const scratch = fs.mkdtempSync(path.join(os.tmpdir(), "cloudcast-k8s-"));
  const file = path.join(scratch, "server.toml");
  fs.writeFileSync(file, text);
  const run = args.map((a) => (a === configPath ? file : a === "$(POD_NAME)" ? "cloudcast-validate-0" : a));
  run[run.indexOf("--listen") + 1] = "127.0.0.1:0";
  run[run.indexOf("--metrics-listen") + 1] = "127.0.0.1:0";
  return new Promise((resolve) => {
    const child = childProcess.spawn(server, run, { stdio: ["ignore", "pipe", "pipe"] });
    let output = "";
    let listening = false;
    const timer = setTimeout(() => child.kill("SIGKILL"), 20000);
    const onData = (d) => {
      output += d;
      if (!listening && /listening on 127\.0\.0\.1:\d+/.test(output)) {
        listening = true;
        child.kill("SIGTERM");
      }
    };
    child.stdout.on("data", onData);
    child.stderr.on("data", onData);
    child.on("exit", (code) => {
      clearTimeout(timer);
      fs.rmSync(scratch, { recursive: true, force: true });
      check(listening, "cloudcast-server starts with the Deployment's args and the ConfigMap's config", output.trim());
      check(listening && code === 0, "and drains on SIGTERM, exit 0", `exit ${code}`);
      resolve();
    });
  });
}

// --- broken copies must fail ------------------------------------------------------------------

function checkBrokenCopiesFail(objects) {
  const deployment = objects.find((o) => o.kind === "Deployment");
  const breakages = {
    "replicas as a string": (d) => { d.spec.replicas = "three"; },
    "a misspelt field (readinesProbe)": (d) => {
      const c = d.spec.template.spec.containers[1];
      c.readinesProbe = c.readinessProbe;
      delete c.readinessProbe;
    },
    "a grpc probe port that is not a number": (d) => {
      d.spec.template.spec.containers[1].readinessProbe.grpc.port = "grpc";
    },
    "no containers list": (d) => { delete d.spec.template.spec.containers; },
    "an unknown field deep in the pod": (d) => { d.spec.template.spec.containers[0].resources.requestz = {}; },
    "a grace period written as \"30s\"": (d) => { d.spec.template.spec.terminationGracePeriodSeconds = "30s"; },
  };
  for (const [what, breakIt] of Object.entries(breakages)) {
    const copy = JSON.parse(JSON.stringify(deployment));
    breakIt(copy);
    const errors = objectErrors(copy);
    check(errors !== "", `a Deployment with ${what} is refused`, "it validated");
  }
  const wrongKind = { ...JSON.parse(JSON.stringify(deployment)), apiVersion: "apps/v2" };
  check(objectErrors(wrongKind) !== "", "an unknown apiVersion is refused");
}

// --- main -----------------------------------------------------------------------------------

async function main() {
  const argv = process.argv.slice(2);
  const dir = argv[0];
  const serverAt = argv.indexOf("--server");
  const server = serverAt >= 0 ? argv[serverAt + 1] : null;
  if (!dir || !fs.statSync(dir).isDirectory()) {
    console.error("usage: node validate.js MANIFEST_DIR [--server PATH/cloudcast-server]");
    process.exit(2);
  }
  const files = fs.readdirSync(dir).filter((f) => /\.ya?ml$/.test(f) && f !== "kustomization.yaml").sort();
  const objects = [];
  for (const f of files) {
    let docs;
    try {
      docs = yaml.loadAll(fs.readFileSync(path.join(dir, f), "utf8")).filter((d) => d != null);
    } catch (e) {
      check(false, `${f} parses as YAML`, e.message);
      continue;
    }
    for (const obj of docs) {
      const name = `${f}: ${obj.kind} ${obj.metadata && obj.metadata.name}`;
      const errors = objectErrors(obj);
      check(errors === "", `${name} matches the Kubernetes schema, every field known`, errors);
      check(!(obj.metadata || {}).namespace, `${name} names no namespace (kubectl -n picks it)`);
      objects.push(obj);
    }
  }
  check(objects.length > 0, `manifests found in ${dir}`);
  checkKustomization(dir, files);
  crossChecks(objects, dir);
  checkBrokenCopiesFail(objects);
  if (server) await checkWithServer(server, objects);
  console.log(`${passed} passed, ${failed} failed`);
  process.exit(failed === 0 ? 0 : 1);
}

main().catch((e) => {
  console.error(e && e.stack ? e.stack : e);
  process.exit(1);
});
