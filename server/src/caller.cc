#include "caller.h"

#include <arpa/inet.h>

#include <algorithm>
#include <functional>
#include <string_view>
#include <utility>

#include "absl/strings/str_cat.h"
#include "frame_input.h"
#include "spdlog/spdlog.h"

namespace cloudcast::server {

absl::Status Caller::CheckTenantPixels(const v1::Frame& frame) const {
  if (tenant == nullptr || tenant->max_pixels == 0) return absl::OkStatus();
  // FramePixels reads the sizes a frame states (raw, compressed) or its image header (PNG,
  // JPEG); what it cannot tell is caught by the core's check against `defaults`' limits.
  const std::uint64_t pixels = FramePixels(frame);
  if (pixels <= tenant->max_pixels) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      "frame.disparity: ", pixels, " pixels (width x height) is over the limit of tenant '",
      tenant->name, "': ", tenant->max_pixels, " pixels per frame (max_pixels in --tokens-file)"));
}

CallerIdentifier::CallerIdentifier(const ServerOptions& options,
                                   std::shared_ptr<const StreamSettings> defaults,
                                   Metrics* metrics)
    : max_pixels_(options.limits.max_pixels), defaults_(std::move(defaults)), metrics_(metrics) {
  for (const std::string& proxy : options.trusted_proxies) {
    trusted_proxies_.push_back(proxy.find(':') == std::string::npos ? "ipv4:" + proxy
                                                                    : "ipv6:[" + proxy + "]");
  }
}

void CallerIdentifier::SetTenants(std::shared_ptr<const TenantDirectory> tenants) {
  std::lock_guard<std::mutex> lock(mu_);
  tenants_ = std::move(tenants);
}

absl::StatusOr<Caller> CallerIdentifier::Identify(grpc::CallbackServerContext* context) {
  std::shared_ptr<const TenantDirectory> tenants;
  {
    std::lock_guard<std::mutex> lock(mu_);
    tenants = tenants_;
  }
  Caller caller;
  if (tenants == nullptr) {
    caller.client.key = PeerHost(context->peer());
    caller.label = context->peer();
    if (std::string forwarded = ForwardedClient(context, caller.client.key); !forwarded.empty()) {
      caller.label = absl::StrCat(context->peer(), " for ", forwarded);
      caller.client.key = std::move(forwarded);
    }
    caller.defaults = defaults_;
    caller.fair_key = std::hash<std::string>{}(caller.client.key);
    return caller;
  }
  auto tenant = tenants->Authenticate(context->client_metadata());
  if (!tenant.ok()) {
    metrics_->calls_unauthenticated.Increment();
    spdlog::debug("call from {} refused: {}", context->peer(),
                  std::string(tenant.status().message()));
    return tenant.status();
  }
  caller.tenant = *std::move(tenant);
  caller.client.key = "tenant:" + caller.tenant->name;
  caller.client.tenant = caller.tenant->name;
  caller.client.max_streams = caller.tenant->max_streams;
  caller.client.max_process = caller.tenant->max_process_in_flight;
  caller.label = absl::StrCat(context->peer(), " (tenant ", caller.tenant->name, ")");
  caller.fair_key = std::hash<std::string>{}(caller.client.key);
  if (caller.tenant->max_pixels > 0 && caller.tenant->max_pixels < max_pixels_) {
    // The core checks every image against these, whatever its encoding.
    auto defaults = std::make_shared<StreamSettings>(*defaults_);
    defaults->frame.pipeline.limits.max_pixels = caller.tenant->max_pixels;
    caller.defaults = std::move(defaults);
  } else {
    caller.defaults = defaults_;
  }
  return caller;
}

std::string CallerIdentifier::ForwardedClient(grpc::CallbackServerContext* context,
                                              const std::string& peer_host) const {
  if (std::find(trusted_proxies_.begin(), trusted_proxies_.end(), peer_host) ==
      trusted_proxies_.end()) {
    return "";
  }
  // "client, proxy1, proxy2", or several headers: the last entry is the one the trusted proxy
  // itself added (a client may send its own header first).
  const auto range = context->client_metadata().equal_range("x-forwarded-for");
  if (range.first == range.second) return "";
  auto last = range.first;
  for (auto it = range.first; it != range.second; ++it) last = it;
  std::string_view value(last->second.data(), last->second.size());
  if (const std::size_t comma = value.rfind(','); comma != std::string_view::npos) {
    value.remove_prefix(comma + 1);
  }
  while (!value.empty() && value.front() == ' ') value.remove_prefix(1);
  while (!value.empty() && value.back() == ' ') value.remove_suffix(1);
  const std::string address(value);
  in_addr v4{};
  in6_addr v6{};
  if (inet_pton(AF_INET, address.c_str(), &v4) == 1) return "ipv4:" + address;
  if (inet_pton(AF_INET6, address.c_str(), &v6) == 1) return "ipv6:[" + address + "]";
  return "";
}

}  // namespace cloudcast::server
