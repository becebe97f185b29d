// Writes the podman kube play variant of docker/k8s's Deployment (with its ConfigMap) for
// ../smoke.sh. podman 4.3 runs it with host networking only (../../PLATFORM.md), so the variant
// differs from the manifest in what host networking forces, and nothing else:
//   - one replica, named NAME;
//   - the image given (the runtime image just built);
//   - --listen and --metrics-listen on a loopback address of the test's (not 0.0.0.0);
//   - no containerPort entries (podman turns them into host port mappings, which host
//     networking refuses).
//
//   node kube-play.js MANIFEST_DIR OUT.yaml NAME IMAGE GRPC_ADDRESS METRICS_ADDRESS
"use strict";
const fs = require("fs");
const path = require("path");
const yaml = require("js-yaml");

const [dir, out, name, image, grpc, metrics] = process.argv.slice(2);
if (!metrics) {
  console.error("usage: node kube-play.js MANIFEST_DIR OUT.yaml NAME IMAGE GRPC_ADDRESS METRICS_ADDRESS");
  process.exit(2);
}
const objects = fs
  .readdirSync(dir)
  .filter((f) => /\.ya?ml$/.test(f) && f !== "kustomization.yaml")
  .flatMap((f) => yaml.loadAll(fs.readFileSync(path.join(dir, f), "utf8")))
  .filter((o) => o != null);
const configMap = objects.find((o) => o.kind === "ConfigMap");
const deployment = objects.find((o) => o.kind === "Deployment");
deployment.metadata.name = name;
deployment.spec.replicas = 1;
const container = deployment.spec.template.spec.containers[0];
container.image = image;
container.imagePullPolicy = "Never";
const set = (flag, value) => {
  const i = container.args.indexOf(flag);
  if (i < 0) throw new Error(`the Deployment's args have no ${flag}`);
  container.args[i + 1] = value;
};
set("--listen", grpc);
set("--metrics-listen", metrics);
delete container.ports;
fs.writeFileSync(out, [configMap, deployment].map((o) => yaml.dump(o)).join("---\n"));
