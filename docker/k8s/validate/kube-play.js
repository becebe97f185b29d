// Writes the podman kube play variant of docker/k8s's Deployment (with its ConfigMaps) for
// ../smoke.sh. podman 4.3 runs it with host networking only (../../PLATFORM.md), so the variant
// differs from the manifest in what host networking forces, and nothing else:
//   - one replica, named NAME;
//   - the images given (the runtime image and the HAProxy image just built);
//   - the addresses on loopback addresses of the test's: the proxy's listening address (the Pod's
//     gRPC port), the server's --listen behind it (the proxy's backend, and its liveness probe),
//     and --metrics-listen;
//   - no containerPort entries (podman turns them into host port mappings, which host
//     networking refuses).
//
//   node kube-play.js MANIFEST_DIR OUT.yaml NAME IMAGE PROXY_IMAGE GRPC_ADDRESS BACKEND_ADDRESS METRICS_ADDRESS
"use strict";
const fs = require("fs");
const path = require("path");
const yaml = require("js-yaml");

const [dir, out, name, image, proxyImage, grpc, backend, metrics] = process.argv.slice(2);
if (!metrics) {
  console.error(
    "usage: node kube-play.js MANIFEST_DIR OUT.yaml NAME IMAGE PROXY_IMAGE GRPC_ADDRESS BACKEND_ADDRESS METRICS_ADDRESS",
  );
  process.exit(2);
}
const objects = fs
  .readdirSync(dir)
  .filter((f) => /\.ya?ml$/.test(f) && f !== "kustomization.yaml")
  .flatMap((f) => yaml.loadAll(fs.readFileSync(path.join(dir, f), "utf8")))
  .filter((o) => o != null);
const configMaps = objects.filter((o) => o.kind === "ConfigMap");
const deployment = objects.find((o) => o.kind === "Deployment");
deployment.metadata.name = name;
deployment.spec.replicas = 1;
const containers = deployment.spec.template.spec.containers;
const server = containers.find((c) => c.name === "server");
const proxy = containers.find((c) => c.name === "proxy");
server.image = image;
proxy.image = proxyImage;
for (const c of containers) {
  c.imagePullPolicy = "Never";
  delete c.ports;
}
const set = (flag, value) => {
  const i = server.args.indexOf(flag);
  if (i < 0) throw new Error(`the server's args have no ${flag}`);
  server.args[i + 1] = value;
};
const listen = server.args[server.args.indexOf("--listen") + 1];
set("--listen", backend);
set("--metrics-listen", metrics);
const live = server.livenessProbe.exec.command;
live[live.indexOf(listen)] = backend;
const env = (key, value) => {
  const e = proxy.env.find((x) => x.name === key);
  if (!e) throw new Error(`the proxy's env has no ${key}`);
  e.value = value;
};
env("CLOUDCAST_PROXY_LISTEN", grpc);
env("CLOUDCAST_BACKEND", backend);
fs.writeFileSync(out, [...configMaps, deployment].map((o) => yaml.dump(o)).join("---\n"));
