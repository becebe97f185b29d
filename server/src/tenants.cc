#include "tenants.h"

#include <openssl/sha.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "nlohmann/json.hpp"

namespace cloudcast::server {
namespace {

using nlohmann::json;

constexpr std::size_t kMinTokenLength = 16;

absl::Status Invalid(const std::string& source, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(source, ": ", what));
}

// A limit: a non-negative integer within `max`.
absl::Status ReadLimit(const json& value, const std::string& source, const std::string& where,
                       const char* key, std::uint64_t max, std::uint64_t* out) {
  if (!value.is_number_unsigned()) {
    return Invalid(source, absl::StrCat(where, ": \"", key, "\" must be a non-negative integer"));
  }
  const std::uint64_t v = value.get<std::uint64_t>();
  if (v > max) {
    return Invalid(source, absl::StrCat(where, ": \"", key, "\" is ", v, "; at most ", max));
  }
  *out = v;
  return absl::OkStatus();
}

}  // namespace

std::size_t TenantDirectory::DigestHash::operator()(const Digest& d) const {
  std::size_t h;
  std::memcpy(&h, d.data(), sizeof h);  // a digest is uniformly distributed already
  return h;
}

TenantDirectory::Digest TenantDirectory::Sha256(std::string_view text) {
  Digest d;
  SHA256(reinterpret_cast<const unsigned char*>(text.data()), text.size(), d.data());
  return d;
}

absl::StatusOr<std::shared_ptr<const TenantDirectory>> TenantDirectory::Parse(
    std::string_view text, const std::string& source, std::uint64_t max_pixels) {
  // No exceptions past this point; nlohmann's messages name the byte offset, never the content.
  const json root = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded()) return Invalid(source, "not valid JSON");
  if (!root.is_object())
    return Invalid(source, "the top level must be an object {\"tenants\": [...]}");
  for (const auto& [key, value] : root.items()) {
    if (key != "tenants") {
      return Invalid(source,
                     absl::StrCat("unknown key \"", key, "\" (the file holds \"tenants\")"));
    }
  }
  if (!root.contains("tenants") || !root["tenants"].is_array()) {
    return Invalid(source, "\"tenants\" must be an array of tenants");
  }
  auto directory = std::make_shared<TenantDirectory>();
  std::set<std::string> names;
  int index = 0;
  for (const json& t : root["tenants"]) {
    const std::string at = absl::StrCat("tenant #", index++);
    if (!t.is_object()) return Invalid(source, absl::StrCat(at, ": must be an object"));
    if (!t.contains("name") || !t["name"].is_string() || t["name"].get<std::string>().empty()) {
      return Invalid(source, absl::StrCat(at, ": \"name\" must be a non-empty string"));
    }
    auto tenant = std::make_shared<Tenant>();
    tenant->name = t["name"].get<std::string>();
    const std::string where = absl::StrCat("tenant '", tenant->name, "'");
    for (char c : tenant->name) {
      if (!absl::ascii_isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') {
        return Invalid(source, absl::StrCat(where,
                                            ": a name holds only letters, digits, '-', '_' "
                                            "and '.' (it appears in logs and messages)"));
      }
    }
    if (!names.insert(tenant->name).second) {
      return Invalid(source, absl::StrCat(where, " is listed twice"));
    }
    std::uint64_t v = 0;
    for (const auto& [key, value] : t.items()) {
      if (key == "name" || key == "tokens") continue;
      if (key == "max_streams") {
        if (auto s = ReadLimit(value, source, where, "max_streams",
                               std::numeric_limits<std::uint32_t>::max(), &v);
            !s.ok()) {
          return s;
        }
        tenant->max_streams = static_cast<std::uint32_t>(v);
      } else if (key == "max_process_in_flight") {
        if (auto s = ReadLimit(value, source, where, "max_process_in_flight",
                               std::numeric_limits<std::uint32_t>::max(), &v);
            !s.ok()) {
          return s;
        }
        tenant->max_process_in_flight = static_cast<std::uint32_t>(v);
      } else if (key == "max_pixels") {
        if (auto s = ReadLimit(value, source, where, "max_pixels", max_pixels, &v); !s.ok()) {
          return absl::InvalidArgumentError(
              absl::StrCat(s.message(), " (the server's --max-pixels)"));
        }
        tenant->max_pixels = v;
      } else {
        return Invalid(source, absl::StrCat(where, ": unknown key \"", key,
                                            "\" (a tenant has name, tokens, max_streams, "
                                            "max_process_in_flight and max_pixels)"));
      }
    }
    if (!t.contains("tokens") || !t["tokens"].is_array() || t["tokens"].empty()) {
      return Invalid(source,
                     absl::StrCat(where, ": \"tokens\" must be a non-empty array of strings"));
    }
    int token_index = 0;
    for (const json& token : t["tokens"]) {
      const std::string tat = absl::StrCat(where, ", token #", token_index++);
      if (!token.is_string()) return Invalid(source, absl::StrCat(tat, ": must be a string"));
      const std::string& value = token.get_ref<const std::string&>();
      if (value.size() < kMinTokenLength) {
        return Invalid(source, absl::StrCat(tat, ": a token has at least ", kMinTokenLength,
                                            " characters (e.g. openssl rand -hex 32)"));
      }
      for (char c : value) {
        // What fits an HTTP header value after "Bearer ".
        if (static_cast<unsigned char>(c) <= ' ' || static_cast<unsigned char>(c) >= 0x7f) {
          return Invalid(source, absl::StrCat(tat, ": a token holds printable ASCII, no spaces"));
        }
      }
      if (!directory->by_token_.emplace(Sha256(value), tenant).second) {
        return Invalid(source, absl::StrCat(tat, ": the same token is listed twice"));
      }
    }
  }
  directory->tenants_ = names.size();
  if (directory->tenants_ == 0) return Invalid(source, "no tenant listed: nobody could connect");
  return std::shared_ptr<const TenantDirectory>(std::move(directory));
}

absl::StatusOr<std::shared_ptr<const TenantDirectory>> TenantDirectory::Load(
    const std::string& path, std::uint64_t max_pixels) {
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tokens-file: cannot read ", path, ": ", std::strerror(errno)));
  }
  std::stringstream ss;
  ss << file.rdbuf();
  return Parse(ss.str(), absl::StrCat("--tokens-file ", path), max_pixels);
}

absl::StatusOr<std::shared_ptr<const Tenant>> TenantDirectory::Authenticate(
    const std::multimap<grpc::string_ref, grpc::string_ref>& metadata) const {
  auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return absl::UnauthenticatedError(
        "this server requires a bearer token: send the metadata \"authorization: Bearer "
        "<token>\" (the programs' --token-file)");
  }
  const std::string_view value(it->second.data(), it->second.size());
  constexpr std::string_view kScheme = "bearer ";
  if (value.size() <= kScheme.size() ||
      !absl::EqualsIgnoreCase(absl::string_view(value.data(), kScheme.size()),
                              absl::string_view(kScheme.data(), kScheme.size()))) {
    return absl::UnauthenticatedError(
        "the authorization metadata is not of the form \"Bearer <token>\"");
  }
  return AuthenticateToken(value.substr(kScheme.size()));
}

absl::StatusOr<std::shared_ptr<const Tenant>> TenantDirectory::AuthenticateToken(
    std::string_view token) const {
  auto it = by_token_.find(Sha256(token));
  if (it == by_token_.end()) {
    return absl::UnauthenticatedError("the bearer token is not valid for this server");
  }
  return it->second;
}

}  // namespace cloudcast::server
