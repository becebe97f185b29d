// ros2-fastdds-peer: a ROS 2 camera and subscriber on Fast DDS (the vendor behind rmw_fastrtps),
// for ros2_bridge_dds_test: it publishes New Tsukuba frames as disparity + left colour + left
// CameraInfo (fastddsgen's types of ros2/idl/ros2_messages.idl, Fast DDS's own CDR), stamped
// 1000 + k s for frame k, every 50 ms, and subscribes to the bridge's PointCloud2. Each cloud it
// receives after the first is written to OUT/<stamp sec>.bin (the data) and .txt (the other
// fields); it exits 0 after --clouds of them, 1 when --seconds pass first, 2 on a bad argument.
//
//   ros2-fastdds-peer --data DIR --namespace /stereo --clouds 7 --out DIR [--seconds 40]
//
// --garbage SECONDS instead writes, for that long, samples that are no valid CDR (random bytes
// behind a CDR_LE header, every 20 ms) on the disparity topic under the DisparityImage type name:
// what a broken or hostile writer sends. Exits 0.
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/datasets/tsukuba.h"
#include "fastdds_ros2_messages.h"
#include "fastdds_ros2_messagesPubSubTypes.h"
#include "type_hash.h"

namespace fdds = eprosima::fastdds::dds;
namespace msg = sensor_msgs::msg::dds_;

namespace {

constexpr double kF = 615.0, kBaseline = 0.1, kCx = 320.0, kCy = 240.0;
constexpr float kMinDisparity = 4.0f;
constexpr const char* kFrameId = "tsukuba_left_optical";

struct Args {
  std::string data, ns = "/stereo", out;
  int clouds = 7;
  double seconds = 40;
  double garbage = 0;
};

// A type under DisparityImage's DDS name whose samples are whatever bytes they hold.
struct RawBytes {
  std::vector<std::uint8_t> bytes;
};
class RawDisparityType : public fdds::TopicDataType {
 public:
  RawDisparityType() {
    setName("stereo_msgs::msg::dds_::DisparityImage_");
    m_typeSize = 1 << 16;
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    const auto& raw = *static_cast<RawBytes*>(data);
    if (raw.bytes.size() > payload->max_size) return false;
    std::memcpy(payload->data, raw.bytes.data(), raw.bytes.size());
    payload->length = static_cast<std::uint32_t>(raw.bytes.size());
    payload->encapsulation = CDR_LE;
    return true;
  }
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t*, void*) override { return false; }
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<uint32_t>(static_cast<RawBytes*>(data)->bytes.size()); };
  }
  void* createData() override { return new RawBytes(); }
  void deleteData(void* data) override { delete static_cast<RawBytes*>(data); }
  bool getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) override { return false; }
};

// As rmw_fastrtps makes them: reliable, keep last 10, volatile, XCDR1, the type hash in
// USER_DATA, sample memory that grows with the sample (clouds of megabytes).
template <typename Qos>
Qos RosQos(Qos qos, const std::string& ros_type) {
  qos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  qos.history().depth = 10;
  qos.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
  qos.endpoint().history_memory_policy =
      eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  const std::string ud = "typehash=" + cloudcast::ros2_bridge::TypeHash(ros_type) + ";";
  qos.user_data().setValue(std::vector<eprosima::fastrtps::rtps::octet>(ud.begin(), ud.end()));
  return qos;
}

std_msgs::msg::dds_::Header_ Header(int k) {
  std_msgs::msg::dds_::Header_ h;
  h.stamp().sec(1000 + k);
  h.stamp().nanosec(0);
  h.frame_id(kFrameId);
  return h;
}

int Usage(const char* why) {
  std::fprintf(stderr,
               "ros2-fastdds-peer: %s\nusage: ros2-fastdds-peer --data DIR --out DIR "
               "[--namespace /stereo] [--clouds 7] [--seconds 40]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string f = argv[i];
    if (i + 1 >= argc) return Usage(("missing value of " + f).c_str());
    const std::string v = argv[++i];
    if (f == "--data") {
      a.data = v;
    } else if (f == "--namespace") {
      a.ns = v;
    } else if (f == "--out") {
      a.out = v;
    } else if (f == "--clouds") {
      a.clouds = std::atoi(v.c_str());
    } else if (f == "--seconds") {
      a.seconds = std::atof(v.c_str());
    } else if (f == "--garbage") {
      a.garbage = std::atof(v.c_str());
    } else {
      return Usage(("unknown flag " + f).c_str());
    }
  }
  if (a.garbage > 0) {
    fdds::DomainParticipant* p =
        fdds::DomainParticipantFactory::get_instance()->create_participant(
            0, fdds::PARTICIPANT_QOS_DEFAULT);
    if (p == nullptr) return Usage("cannot create the Fast DDS participant");
    fdds::TypeSupport raw(new RawDisparityType());
    raw.register_type(p);
    fdds::Topic* t = p->create_topic("rt" + a.ns + "/disparity", raw.get_type_name(),
                                     fdds::TOPIC_QOS_DEFAULT);
    fdds::Publisher* pub = p->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    fdds::DataWriter* w = pub->create_datawriter(
        t, RosQos(fdds::DATAWRITER_QOS_DEFAULT, "stereo_msgs/msg/DisparityImage"));
    if (w == nullptr) return Usage("cannot create the Fast DDS writer");
    std::srand(1);
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(a.garbage);
    while (std::chrono::steady_clock::now() < end) {
      RawBytes sample;
      sample.bytes.resize(1 + static_cast<std::size_t>(std::rand() % 2000));
      for (auto& b : sample.bytes) b = static_cast<std::uint8_t>(std::rand());
      // Lengths that claim more than there is: the first field, the header's stamp, then a
      // string length of ~2 GB.
      if (sample.bytes.size() > 12) std::memset(sample.bytes.data() + 8, 0x7f, 4);
      w->write(&sample);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    p->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(p);
    return 0;
  }
  if (a.data.empty() || a.out.empty()) return Usage("--data and --out are required");

  // The frames' messages, built once.
  std::vector<stereo_msgs::msg::dds_::DisparityImage_> disparities;
  std::vector<msg::Image_> colours;
  for (const char* id : {"00001", "00200", "00400"}) {
    auto frame = cloudcast::tsukuba::Load(a.data, id);
    if (!frame.ok()) return Usage(std::string(frame.status().message()).c_str());
    const std::uint32_t w = frame->disparity.width, h = frame->disparity.height;
    std::vector<std::uint8_t> bytes(std::size_t{w} * h * 4);
    for (std::size_t p = 0; p < std::size_t{w} * h; ++p) {
      const std::uint8_t d8 = frame->disparity.pixels[p];
      const float d = d8 == 0 ? kMinDisparity - 1.0f : static_cast<float>(d8);
      std::memcpy(bytes.data() + 4 * p, &d, 4);
    }
    stereo_msgs::msg::dds_::DisparityImage_ dm;
    dm.image().width(w);
    dm.image().height(h);
    dm.image().encoding("32FC1");
    dm.image().step(w * 4);
    dm.image().data(std::move(bytes));
    dm.f(static_cast<float>(kF));
    dm.t(static_cast<float>(kBaseline));
    dm.valid_window().width(w);
    dm.valid_window().height(h);
    dm.min_disparity(kMinDisparity);
    dm.max_disparity(255.0f);
    dm.delta_d(1.0f);
    disparities.push_back(std::move(dm));
    msg::Image_ c;
    c.width(frame->colour.width);
    c.height(frame->colour.height);
    c.encoding("bgr8");
    c.step(frame->colour.width * 3);
    c.data(frame->colour.pixels);
    colours.push_back(std::move(c));
  }
  msg::CameraInfo_ info;
  info.width(640);
  info.height(480);
  info.distortion_model("plumb_bob");
  info.d(std::vector<double>(5, 0.0));
  info.k({kF, 0, kCx, 0, kF, kCy, 0, 0, 1});
  info.r({1, 0, 0, 0, 1, 0, 0, 0, 1});
  info.p({kF, 0, kCx, 0, 0, kF, kCy, 0, 0, 0, 1, 0});

  fdds::DomainParticipantQos pqos;
  const std::string enclave = "enclave=/;";
  pqos.user_data().setValue(std::vector<eprosima::fastrtps::rtps::octet>(enclave.begin(), enclave.end()));
  pqos.name("ros2_fastdds_peer");
  const char* domain_env = std::getenv("ROS_DOMAIN_ID");
  const int domain = domain_env != nullptr ? std::atoi(domain_env) : 0;
  fdds::DomainParticipant* participant =
      fdds::DomainParticipantFactory::get_instance()->create_participant(domain, pqos);
  if (participant == nullptr) return Usage("cannot create the Fast DDS participant");
  fdds::TypeSupport disparity_type(new stereo_msgs::msg::dds_::DisparityImage_PubSubType());
  fdds::TypeSupport image_type(new msg::Image_PubSubType());
  fdds::TypeSupport info_type(new msg::CameraInfo_PubSubType());
  fdds::TypeSupport cloud_type(new msg::PointCloud2_PubSubType());
  for (auto* t : {&disparity_type, &image_type, &info_type, &cloud_type}) {
    t->register_type(participant);
  }
  fdds::Publisher* pub = participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::Subscriber* sub = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  auto topic = [&](const std::string& name, fdds::TypeSupport& t) {
    return participant->create_topic("rt" + a.ns + "/" + name, t.get_type_name(),
                                     fdds::TOPIC_QOS_DEFAULT);
  };
  fdds::DataWriter* wd = pub->create_datawriter(
      topic("disparity", disparity_type),
      RosQos(fdds::DATAWRITER_QOS_DEFAULT, "stereo_msgs/msg/DisparityImage"));
  fdds::DataWriter* wc = pub->create_datawriter(
      topic("left/image_rect_color", image_type),
      RosQos(fdds::DATAWRITER_QOS_DEFAULT, "sensor_msgs/msg/Image"));
  fdds::DataWriter* wi = pub->create_datawriter(
      topic("left/camera_info", info_type),
      RosQos(fdds::DATAWRITER_QOS_DEFAULT, "sensor_msgs/msg/CameraInfo"));
  fdds::DataReader* rp = sub->create_datareader(
      topic("points2", cloud_type),
      RosQos(fdds::DATAREADER_QOS_DEFAULT, "sensor_msgs/msg/PointCloud2"));
  if (wd == nullptr || wc == nullptr || wi == nullptr || rp == nullptr) {
    return Usage("cannot create the Fast DDS readers and writers");
  }

  // Frame by frame: the next frame goes out once this one's cloud is in (or after a second while
  // no cloud has come: discovery may drop the first frames; 10 s after). Publishing at a fixed
  // 20 Hz instead let Cyclone's writer replace 5 MB clouds that Fast DDS's reader was still
  // repairing fragment by fragment (UDP between the two vendors): on a loaded machine (CI's,
  // or six busy processes on two cores) 0 to 5 of 6 clouds arrived in 40 s while the bridge
  // published 748.
  using Clock = std::chrono::steady_clock;
  int received = 0, seen = 0;
  const Clock::time_point end =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(a.seconds));
  for (int k = 0; Clock::now() < end; ++k) {
    const std::size_t f = static_cast<std::size_t>(k) % disparities.size();
    disparities[f].header(Header(k));
    disparities[f].image().header(Header(k));
    colours[f].header(Header(k));
    info.header(Header(k));
    wd->write(&disparities[f]);
    wc->write(&colours[f]);
    wi->write(&info);
    const Clock::time_point give_up =
        std::min(end, Clock::now() + std::chrono::seconds(seen == 0 ? 1 : 10));
    bool answered = false;
    while (!answered && Clock::now() < give_up) {
      const double left = std::chrono::duration<double>(give_up - Clock::now()).count();
      rp->wait_for_unread_message(eprosima::fastrtps::Duration_t(left));
      msg::PointCloud2_ cloud;
      fdds::SampleInfo si;
      while (rp->take_next_sample(&cloud, &si) == ReturnCode_t::RETCODE_OK) {
        if (!si.valid_data) continue;
        answered = answered || cloud.header().stamp().sec() == 1000 + k;
        if (seen++ == 0) continue;  // later samples only (discovery may drop the first ones)
        const std::string base = a.out + "/" + std::to_string(cloud.header().stamp().sec());
        std::ofstream(base + ".bin", std::ios::binary)
            .write(reinterpret_cast<const char*>(cloud.data().data()),
                   static_cast<std::streamsize>(cloud.data().size()));
        std::ofstream txt(base + ".txt");
        txt << cloud.header().frame_id() << " " << cloud.header().stamp().nanosec() << " "
            << cloud.height() << " " << cloud.width() << " " << cloud.point_step() << " "
            << cloud.row_step() << " " << cloud.is_dense() << " " << cloud.is_bigendian();
        for (const auto& field : cloud.fields()) {
          txt << " " << field.name() << ":" << field.offset() << ":" << int(field.datatype())
              << ":" << field.count();
        }
        txt << "\n";
        if (++received >= a.clouds) {
          participant->delete_contained_entities();
          fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
          return 0;
        }
      }
    }
  }
  std::fprintf(stderr, "ros2-fastdds-peer: %d of %d clouds in %.0f s\n", received, a.clouds,
               a.seconds);
  participant->delete_contained_entities();
  fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  return 1;
}
