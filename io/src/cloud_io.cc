// PCD and PLY through PCL's own readers and writers (the reference for those formats), DRC through
// our Draco codec. PCL stays inside this translation unit, so nothing else sees PCL or Eigen.
#include "cloudcast/io/cloud_io.h"

#include <pcl/PCLPointCloud2.h>
#include <pcl/PCLPointField.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

namespace cloudcast {
namespace {

constexpr std::uint32_t kWhite = PackRgba(255, 255, 255);

bool IsFinite(const Point& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

std::string Quoted(const std::string& path) { return absl::StrCat("'", path, "'"); }

// Organized clouds whose point count disagrees with width x height would make PCL write a header
// that contradicts its data, so they are refused up front.
absl::Status CheckShape(const std::string& path, const PointCloud& cloud) {
  if (cloud.organized() &&
      std::uint64_t{cloud.width} * cloud.height != static_cast<std::uint64_t>(cloud.size())) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write ", Quoted(path), ": the cloud is organized ", cloud.width, "x",
                     cloud.height, " but holds ", cloud.size(), " points"));
  }
  return absl::OkStatus();
}

// Copies points (all, or only the finite ones) into PCL's layout; colour bits travel unchanged
// because PointXYZRGB's rgba word uses the same 0xAARRGGBB packing as ours.
pcl::PointCloud<pcl::PointXYZRGB> ToPcl(const PointCloud& cloud, bool finite_only) {
  pcl::PointCloud<pcl::PointXYZRGB> out;
  out.reserve(cloud.size());
  bool dense = true;
  for (const Point& p : cloud.points) {
    const bool finite = IsFinite(p);
    if (finite_only && !finite) continue;
    dense = dense && finite;
    pcl::PointXYZRGB q;
    q.x = p.x;
    q.y = p.y;
    q.z = p.z;
    q.rgba = p.rgba;
    out.push_back(q);
  }
  if (!finite_only && cloud.organized()) {
    out.width = cloud.width;
    out.height = cloud.height;
  } else {
    out.width = static_cast<std::uint32_t>(out.size());
    out.height = 1;
  }
  out.is_dense = dense;
  return out;
}

enum class Format { kPcd, kPly, kDrc, kUnknown };

std::string LowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

Format FormatOf(const std::string& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".pcd") return Format::kPcd;
  if (ext == ".ply") return Format::kPly;
  if (ext == ".drc") return Format::kDrc;
  return Format::kUnknown;
}

const pcl::PCLPointField* FindField(const pcl::PCLPointCloud2& blob, const char* name) {
  for (const pcl::PCLPointField& f : blob.fields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

std::size_t SizeOf(std::uint8_t datatype) {
  switch (datatype) {
    case pcl::PCLPointField::INT8:
    case pcl::PCLPointField::UINT8:
      return 1;
    case pcl::PCLPointField::INT16:
    case pcl::PCLPointField::UINT16:
      return 2;
    case pcl::PCLPointField::INT32:
    case pcl::PCLPointField::UINT32:
    case pcl::PCLPointField::FLOAT32:
      return 4;
    case pcl::PCLPointField::FLOAT64:
      return 8;
  }
  return 0;
}

template <typename T>
T Load(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

double ReadScalar(const std::uint8_t* p, std::uint8_t datatype) {
  switch (datatype) {
    case pcl::PCLPointField::INT8:
      return Load<std::int8_t>(p);
    case pcl::PCLPointField::UINT8:
      return Load<std::uint8_t>(p);
    case pcl::PCLPointField::INT16:
      return Load<std::int16_t>(p);
    case pcl::PCLPointField::UINT16:
      return Load<std::uint16_t>(p);
    case pcl::PCLPointField::INT32:
      return Load<std::int32_t>(p);
    case pcl::PCLPointField::UINT32:
      return Load<std::uint32_t>(p);
    case pcl::PCLPointField::FLOAT32:
      return Load<float>(p);
    case pcl::PCLPointField::FLOAT64:
      return Load<double>(p);
  }
  return std::nan("");
}

// Converts what PCL read into our layout, field by field rather than with fromPCLPointCloud2,
// because that needs exact field types: Open3D writes PLY coordinates as double, and other tools
// store rgb as an integer. Organized clouds (height > 1 and a full grid) keep their NaN points,
// with colour 0 as the pipeline makes them; unorganized clouds keep only finite points, as
// point.h requires. Files without colour give white; colour without alpha (PCL's PLY reader
// fills "rgb" from red/green/blue with alpha 0) gives alpha 255.
absl::Status FromPcl(const std::string& path, const pcl::PCLPointCloud2& blob, Format format,
                     PointCloud* out) {
  const pcl::PCLPointField* axes[3] = {FindField(blob, "x"), FindField(blob, "y"),
                                       FindField(blob, "z")};
  for (int a = 0; a < 3; ++a) {
    if (axes[a] == nullptr || SizeOf(axes[a]->datatype) == 0) {
      return absl::InvalidArgumentError(absl::StrCat(Quoted(path), " has no numeric '",
                                                     std::string(1, "xyz"[a]),
                                                     "' field; it is not a point cloud"));
    }
  }
  const pcl::PCLPointField* colour = FindField(blob, "rgba");
  if (colour == nullptr) colour = FindField(blob, "rgb");
  if (colour != nullptr && SizeOf(colour->datatype) != 4) colour = nullptr;
  const bool has_alpha = colour != nullptr && (colour->name == "rgba" || format == Format::kPcd);

  const std::uint64_t width = blob.width, height = blob.height;
  const std::uint64_t count = width * height;
  if (blob.point_step == 0 || blob.row_step < width * blob.point_step ||
      blob.data.size() < height * blob.row_step) {
    return absl::InvalidArgumentError(absl::StrCat(Quoted(path), " holds ", blob.data.size(),
                                                   " bytes, too few for its ", width, "x", height,
                                                   " points"));
  }
  for (const pcl::PCLPointField* f : {axes[0], axes[1], axes[2], colour}) {
    if (f != nullptr && f->offset + SizeOf(f->datatype) > blob.point_step) {
      return absl::InvalidArgumentError(
          absl::StrCat(Quoted(path), ": field '", f->name, "' lies outside its point"));
    }
  }
  const bool organized = height > 1;
  out->points.clear();
  out->points.reserve(count);
  for (std::uint64_t v = 0; v < height; ++v) {
    const std::uint8_t* row = blob.data.data() + v * blob.row_step;
    for (std::uint64_t u = 0; u < width; ++u) {
      const std::uint8_t* q = row + u * blob.point_step;
      Point p;
      p.x = static_cast<float>(ReadScalar(q + axes[0]->offset, axes[0]->datatype));
      p.y = static_cast<float>(ReadScalar(q + axes[1]->offset, axes[1]->datatype));
      p.z = static_cast<float>(ReadScalar(q + axes[2]->offset, axes[2]->datatype));
      p.rgba = 0;
      if (IsFinite(p)) {
        if (colour == nullptr) {
          p.rgba = kWhite;
        } else {
          p.rgba = Load<std::uint32_t>(q + colour->offset);
          if (!has_alpha) p.rgba |= 0xFF000000u;
        }
      } else if (!organized) {
        continue;
      }
      out->points.push_back(p);
    }
  }
  if (organized) {
    out->width = blob.width;
    out->height = blob.height;
  } else {
    out->width = static_cast<std::uint32_t>(out->points.size());
    out->height = 1;
  }
  return absl::OkStatus();
}

absl::Status WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) {
    return absl::UnavailableError(absl::StrCat("cannot open ", Quoted(path), " for writing"));
  }
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();
  if (!file) {
    return absl::UnavailableError(absl::StrCat("writing ", Quoted(path), " failed"));
  }
  return absl::OkStatus();
}

absl::Status ReadBytes(const std::string& path, std::string* bytes) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return absl::UnavailableError(absl::StrCat("cannot open ", Quoted(path)));
  bytes->assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  if (file.bad()) return absl::UnavailableError(absl::StrCat("reading ", Quoted(path), " failed"));
  return absl::OkStatus();
}

// PCL refuses to write an empty PLY and to read an empty PCD or PLY, but an empty result is
// normal (a passthrough range nobody is in). Empty files are written by hand in PCL's layout.
std::string EmptyFile(Format format) {
  if (format == Format::kPcd) {
    return pcl::PCDWriter::generateHeader(pcl::PointCloud<pcl::PointXYZRGB>()) + "DATA binary\n";
  }
  return "ply\nformat binary_little_endian 1.0\ncomment PCL generated\nelement vertex 0\n"
         "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
         "property uchar green\nproperty uchar blue\nend_header\n";
}

// PCL's readers trust their headers: a PCD without FIELDS or POINTS crashes PCDReader::read, and
// a header promising more points than the file holds makes PCL zero-fill (and so commit) memory
// for all of them first. So headers are checked here, and the body size they imply compared with
// the file, before PCL sees the file. Returns the declared point count.
absl::StatusOr<std::uint64_t> CheckPcdHeader(const std::string& path, std::istream& in,
                                             std::uint64_t file_size) {
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(
        absl::StrCat(Quoted(path), " is not a valid PCD file: ", why));
  };
  std::vector<std::string> fields, sizes, types, counts;
  std::uint64_t width = 0, height = 1, points = 0;
  bool have_width = false, have_points = false;
  std::string data, line;
  auto words = [](const std::string& l) {
    std::istringstream ss(l);
    std::vector<std::string> w;
    for (std::string t; ss >> t;) w.push_back(t);
    return w;
  };
  auto number = [](const std::string& t, std::uint64_t* v) {
    if (t.empty() || t.size() > 12 || t.find_first_not_of("0123456789") != std::string::npos) {
      return false;
    }
    *v = std::stoull(t);
    return true;
  };
  // PCL's rules: keywords match by prefix, '#' starts a comment, empty lines are skipped, and
  // the first line that is none of these ends the header (DATA does not). Mirroring them means
  // both parsers see the same header.
  // The PCD format also fixes the entries' order, each at most once. PCL does not check it: it
  // sizes its buffer from the entries seen when POINTS comes, so a FIELDS, SIZE or TYPE repeated
  // after it makes readBodyASCII write past that buffer (valgrind: "Invalid write of size 4 ...
  // 16 bytes after a block of size 64"; our fuzzer saw the heap corrupted later). Refused here.
  static constexpr const char* kOrder[] = {"VERSION", "FIELDS", "SIZE",      "TYPE",   "COUNT",
                                           "WIDTH",   "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};
  int last_entry = -1;
  std::streamoff data_at = -1;
  for (int i = 0; i < 4096 && std::getline(in, line); ++i) {
    if (line.empty()) continue;
    const std::vector<std::string> w = words(line);
    const std::string key = w.empty() ? std::string() : w[0];
    auto is = [&key](const char* k) { return key.rfind(k, 0) == 0; };
    const std::vector<std::string> rest(w.empty() ? w.end() : w.begin() + 1, w.end());
    if (is("#")) continue;
    for (int e = 0; e < static_cast<int>(std::size(kOrder)); ++e) {
      if (!(is(kOrder[e]) || (e == 1 && is("COLUMNS")))) continue;
      if (e <= last_entry) {
        return bad(absl::StrCat(kOrder[e], " comes after ", kOrder[last_entry],
                                "; the header's entries go once each, in the order VERSION, "
                                "FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS, "
                                "DATA"));
      }
      last_entry = e;
      break;
    }
    if (is("VERSION")) continue;
    if (is("FIELDS") || is("COLUMNS")) {
      fields = rest;
    } else if (is("SIZE")) {
      sizes = rest;
    } else if (is("TYPE")) {
      types = rest;
    } else if (is("COUNT")) {
      counts = rest;
    } else if (is("WIDTH")) {
      have_width = rest.size() == 1 && number(rest[0], &width);
      if (!have_width) return bad("bad WIDTH");
    } else if (is("HEIGHT")) {
      if (!(rest.size() == 1 && number(rest[0], &height))) return bad("bad HEIGHT");
    } else if (is("VIEWPOINT")) {
      if (rest.size() < 7) return bad("VIEWPOINT needs 7 values");
    } else if (is("POINTS")) {
      have_points = rest.size() == 1 && number(rest[0], &points);
      if (!have_points) return bad("bad POINTS");
    } else if (is("DATA")) {
      if (rest.empty()) return bad("DATA names no format");
      data = rest[0].rfind("binary_compressed", 0) == 0 ? "binary_compressed"
             : rest[0].rfind("binary", 0) == 0          ? "binary"
                                                        : "ascii";
      data_at = in.tellg();
    } else {
      break;
    }
  }
  if (data.empty()) return bad("no DATA line in its header");
  if (fields.empty()) return bad("no FIELDS");
  if (sizes.size() != fields.size() || types.size() != fields.size() ||
      (!counts.empty() && counts.size() != fields.size())) {
    return bad("FIELDS, SIZE, TYPE and COUNT disagree in length");
  }
  if (!have_points && !have_width) return bad("neither POINTS nor WIDTH");
  if (!have_points) points = width * height;
  if (have_width && width * height != points) return bad("WIDTH x HEIGHT differs from POINTS");
  std::uint64_t point_step = 0;
  for (std::size_t f = 0; f < fields.size(); ++f) {
    std::uint64_t size = 0, count = 1;
    if (!number(sizes[f], &size) || (size != 1 && size != 2 && size != 4 && size != 8) ||
        types[f].size() != 1 || std::string("IUF").find(types[f][0]) == std::string::npos ||
        (!counts.empty() && (!number(counts[f], &count) || count == 0 || count > 65536))) {
      return bad(absl::StrCat("bad SIZE, TYPE or COUNT for field '", fields[f], "'"));
    }
    point_step += size * count;
  }
  if (points > std::uint64_t{INT32_MAX}) return bad("more points than PCL can hold");
  if (points == 0) return points;
  if (data_at < 0 || static_cast<std::uint64_t>(data_at) > file_size) {
    return bad("truncated header");
  }
  const std::uint64_t body = file_size - static_cast<std::uint64_t>(data_at);
  in.clear();
  in.seekg(data_at);
  if (data == "binary") {
    if (points * point_step > body) {
      return bad(absl::StrCat("POINTS ", points, " need ", points * point_step,
                              " bytes, the file "
                              "holds ",
                              body));
    }
  } else if (data == "binary_compressed") {
    std::uint32_t sizes_word[2] = {0, 0};
    in.read(reinterpret_cast<char*>(sizes_word), sizeof(sizes_word));
    if (!in || std::uint64_t{sizes_word[0]} + 8 > body ||
        std::uint64_t{sizes_word[1]} != points * point_step) {
      return bad("its compressed body does not match its header");
    }
  } else if (points * fields.size() * 2 > body + 1) {
    // ascii: every value needs at least a digit and a separator.
    return bad("fewer values than POINTS promises");
  }
  return points;
}

// PCL's PLY reader is stricter still: it asserts (aborting the process) when a vertex is written
// outside the buffer it sized from the header, which obj_info num_cols/num_rows, a camera element
// before the vertices, list properties on vertices or an incomplete red/green/blue set can cause.
// Only headers whose layout PCL handles safely are passed on; the rest are refused by name.
absl::StatusOr<std::uint64_t> CheckPlyHeader(const std::string& path, std::istream& in,
                                             std::uint64_t file_size) {
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(absl::StrCat(Quoted(path),
                                                   " is not a PLY file cloudcast "
                                                   "reads: ",
                                                   why));
  };
  auto type_size = [](const std::string& t) -> std::uint64_t {
    if (t == "char" || t == "int8" || t == "uchar" || t == "uint8") return 1;
    if (t == "short" || t == "int16" || t == "ushort" || t == "uint16") return 2;
    if (t == "int" || t == "int32" || t == "uint" || t == "uint32" || t == "float" ||
        t == "float32") {
      return 4;
    }
    if (t == "double" || t == "float64") return 8;
    return 0;
  };
  std::string line;
  if (!std::getline(in, line) || line.rfind("ply", 0) != 0) return bad("it does not start 'ply'");
  // PCL splits the header as its first line ends: at carriage returns, skipping the character
  // after each (CRLF), when the fourth byte is '\r'; at line feeds otherwise. Lines are read here
  // at line feeds, so a CRLF header must have every line end in exactly "\r\n": a bare CR hid
  // lines from these checks that PCL then read (an element range_grid inside a "comment" made PCL
  // 1.13 copy from 4 GB past its buffer), and a bare LF joins two lines for PCL. Control
  // characters other than tab split words for one parser and not the other (PCL splits obj_info
  // at blanks and tabs only), so header lines are plain text.
  const bool crlf = line.size() > 3 && line[3] == '\r';
  int line_number = 1;
  auto text_line = [&](std::string* l) -> absl::Status {
    const bool ends_in_cr = !l->empty() && l->back() == '\r';
    if (crlf && !ends_in_cr && !in.eof()) {
      return bad(absl::StrCat("line ", line_number,
                              " ends in a bare line feed in a header whose lines end in "
                              "carriage return + line feed"));
    }
    if (ends_in_cr) l->pop_back();
    for (const char c : *l) {
      if (c == '\r') {
        return bad(absl::StrCat("line ", line_number, " holds a carriage return before its end"));
      }
      if ((static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7f) {
        return bad(absl::StrCat("line ", line_number, " holds control character ",
                                static_cast<int>(static_cast<unsigned char>(c))));
      }
    }
    return absl::OkStatus();
  };
  if (crlf && line != "ply\r") return bad("its first line is not 'ply'");
  struct Element {
    std::string name;
    std::uint64_t count = 0, min_step = 0, properties = 0;
    bool has_list = false;
    std::vector<std::string> uchar_colours;  // red/green/blue (or diffuse_*) in file order
  };
  std::vector<Element> elements;
  std::string format;
  bool ended = false;
  // PCL's width and height as its reader sets them while walking the header.
  std::uint64_t width = 0, height = 0;
  for (int i = 0; i < 10000 && !ended && std::getline(in, line); ++i) {
    ++line_number;
    if (absl::Status s = text_line(&line); !s.ok()) return s;
    std::istringstream ss(line);
    std::string key;
    ss >> key;
    if (key == "format") {
      ss >> format;
    } else if (key == "obj_info") {
      // PCL splits the whole line on blanks and asserts the first word is obj_info.
      if (line.rfind("obj_info", 0) != 0) return bad("indented obj_info line");
      std::string what, value;
      ss >> what >> value;
      const auto v = static_cast<std::uint32_t>(std::atoi(value.c_str()));
      if (what == "num_cols") width = v;
      if (what == "num_rows") height = v;
    } else if (key == "element") {
      Element e;
      std::string count;
      ss >> e.name >> count;
      if (count.empty() || count.size() > 10 ||
          count.find_first_not_of("0123456789") != std::string::npos) {
        return bad(absl::StrCat("bad count for element '", e.name, "'"));
      }
      e.count = std::stoull(count);
      if (e.name == "range_grid") return bad("PCL range_grid elements are not supported");
      if (e.name == "vertex" && (width == 0 || height == 0)) {
        width = e.count;
        height = 1;
      }
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) return bad("a property before any element");
      Element& e = elements.back();
      std::string type, count_type, name;
      ss >> type;
      std::uint64_t size = 0;
      if (type == "list") {
        ss >> count_type >> type >> name;
        size = type_size(count_type);  // a list holds at least its count
        e.has_list = true;
      } else {
        ss >> name;
        size = type_size(type);
      }
      if (size == 0 || type_size(type) == 0) {
        return bad(absl::StrCat("unknown property type in '", line, "'"));
      }
      if (e.name == "camera" && (name == "viewportx" || name == "viewporty") &&
          std::none_of(elements.begin(), elements.end(),
                       [](const Element& x) { return x.name == "vertex"; })) {
        return bad("a camera viewport before the vertices");
      }
      if (size == 1 && (type == "uchar" || type == "uint8")) {
        for (const char* c : {"red", "green", "blue"}) {
          if (name == c || name == std::string("diffuse_") + c) e.uchar_colours.push_back(c);
        }
      }
      e.min_step += size;
      ++e.properties;
    } else if (key == "end_header") {
      ended = true;
    }
  }
  if (!ended) return bad("no end_header");
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") {
    return bad(absl::StrCat("unknown format '", format, "'"));
  }
  const std::streamoff at = in.tellg();
  if (at < 0) return bad("truncated header");
  const std::uint64_t body = file_size - static_cast<std::uint64_t>(at);
  std::uint64_t needed = 0;
  const Element* vertex = nullptr;
  for (const Element& e : elements) {
    // ascii: at least a digit and a separator per value.
    const std::uint64_t step = format == "ascii" ? 2 * e.properties : e.min_step;
    if (step > 0 && e.count > body / step + 1) {
      return bad(absl::StrCat(e.count, " ", e.name, " elements cannot fit in ", body, " bytes"));
    }
    needed += e.count * step;
    if (e.name == "vertex" && vertex == nullptr) vertex = &e;
  }
  if (vertex == nullptr) return bad("no vertex element");
  if (needed > body + 1) {
    return bad(absl::StrCat("its elements need ", needed, " bytes, the file holds ", body));
  }
  if (vertex->count > std::uint64_t{INT32_MAX}) return bad("too many vertices");
  if (vertex->has_list) return bad("list properties on vertices");
  if (!vertex->uchar_colours.empty() &&
      vertex->uchar_colours != std::vector<std::string>{"red", "green", "blue"}) {
    return bad("vertex colour must be uchar red, green, blue in that order");
  }
  if (width * height != vertex->count) {
    return bad(absl::StrCat("obj_info num_cols x num_rows (", width, "x", height,
                            ") differs from its ", vertex->count, " vertices"));
  }
  return vertex->count;
}

absl::StatusOr<std::uint64_t> CheckHeader(const std::string& path, Format format) {
  std::error_code ec;
  const std::uint64_t size = std::filesystem::file_size(path, ec);
  std::ifstream in(path, std::ios::binary);
  if (ec || !in) return absl::UnavailableError(absl::StrCat("cannot open ", Quoted(path)));
  return format == Format::kPcd ? CheckPcdHeader(path, in, size) : CheckPlyHeader(path, in, size);
}

absl::Status SaveWithPcl(const std::string& path, const PointCloud& cloud, Format format) {
  if (auto s = CheckShape(path, cloud); !s.ok()) return s;
  // PLY has no invalid vertices, so only the finite points go there.
  const pcl::PointCloud<pcl::PointXYZRGB> pcl_cloud =
      ToPcl(cloud, /*finite_only=*/format == Format::kPly);
  if (pcl_cloud.empty()) return WriteBytes(path, EmptyFile(format));
  int rc = 0;
  if (format == Format::kPcd) {
    rc = pcl::io::savePCDFileBinary(path, pcl_cloud);
  } else {
    // No camera element: it is a PCL extension that other readers only have to skip.
    pcl::PLYWriter writer;
    rc = writer.write(path, pcl_cloud, /*binary=*/true, /*use_camera=*/false);
  }
  if (rc < 0) {
    return absl::UnavailableError(
        absl::StrCat("PCL could not write ", Quoted(path), " (is it writable?)"));
  }
  return absl::OkStatus();
}

absl::Status LoadWithPcl(const std::string& path, Format format, PointCloud* out) {
  const absl::StatusOr<std::uint64_t> points = CheckHeader(path, format);
  if (!points.ok()) return points.status();
  if (*points == 0) {
    out->points.clear();
    out->width = 0;
    out->height = 1;
    return absl::OkStatus();
  }
  pcl::PCLPointCloud2 blob;
  const int rc =
      format == Format::kPcd ? pcl::io::loadPCDFile(path, blob) : pcl::io::loadPLYFile(path, blob);
  if (rc < 0) {
    return absl::InvalidArgumentError(absl::StrCat("PCL could not read ", Quoted(path), " as ",
                                                   format == Format::kPcd ? "PCD" : "PLY"));
  }
  return FromPcl(path, blob, format, out);
}

absl::Status MissingFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return absl::NotFoundError(absl::StrCat("cannot read ", Quoted(path), ": no such file"));
  }
  if (std::filesystem::is_directory(path, ec)) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot read ", Quoted(path), ": it is a directory"));
  }
  return absl::OkStatus();
}

}  // namespace

const char* SupportedCloudExtensions() { return ".pcd, .ply, .drc"; }

absl::Status CheckCloudPath(const std::string& path) {
  if (FormatOf(path) != Format::kUnknown) return absl::OkStatus();
  const std::string ext = LowerExtension(path);
  return absl::InvalidArgumentError(
      absl::StrCat(Quoted(path), ": ",
                   ext.empty() ? std::string("no file extension")
                               : absl::StrCat("unknown extension '", ext, "'"),
                   "; supported: ", SupportedCloudExtensions()));
}

absl::Status SaveCloud(const std::string& path, const PointCloud& cloud,
                       const DracoOptions& draco) {
  if (auto s = CheckCloudPath(path); !s.ok()) return s;
  // PCL's own message for this case is a bare "Error during open!".
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && !std::filesystem::is_directory(parent, ec)) {
    return absl::NotFoundError(absl::StrCat("cannot write ", Quoted(path), ": folder ",
                                            Quoted(parent.string()), " does not exist"));
  }
  try {
    const Format format = FormatOf(path);
    if (format == Format::kDrc) {
      std::string bytes;
      if (auto s = EncodeDraco(cloud, draco, &bytes); !s.ok()) {
        return absl::Status(s.code(),
                            absl::StrCat("Draco encode for ", Quoted(path), ": ", s.message()));
      }
      return WriteBytes(path, bytes);
    }
    return SaveWithPcl(path, cloud, format);
  } catch (const std::exception& e) {
    // PCL reports some I/O failures (open, mmap) by throwing pcl::IOException, whose what()
    // starts with ": ".
    std::string why = e.what();
    if (why.rfind(": ", 0) == 0) why.erase(0, 2);
    return absl::UnavailableError(absl::StrCat("cannot write ", Quoted(path), ": ", why));
  }
}

absl::Status LoadCloud(const std::string& path, PointCloud* out) {
  if (auto s = CheckCloudPath(path); !s.ok()) return s;
  if (auto s = MissingFile(path); !s.ok()) return s;
  try {
    const Format format = FormatOf(path);
    if (format == Format::kDrc) {
      std::string bytes;
      if (auto s = ReadBytes(path, &bytes); !s.ok()) return s;
      if (auto s = DecodeDraco(bytes, out); !s.ok()) {
        return absl::Status(s.code(),
                            absl::StrCat("Draco decode of ", Quoted(path), ": ", s.message()));
      }
      return absl::OkStatus();
    }
    return LoadWithPcl(path, format, out);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("cannot read ", Quoted(path), ": ", e.what()));
  }
}

}  // namespace cloudcast
