// Forged H.264 sequence headers for the bad-input tests (video_codec_test, video_uplink_test): an
// SPS written field by field, so that a test can claim any picture size in a few bytes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cloudcast::testing {

// Writes an SPS bit by bit (Baseline, no VUI), with emulation prevention.
class SpsWriter {
 public:
  void U(int n, std::uint32_t v) {
    for (int i = n - 1; i >= 0; --i) bits_.push_back((v >> i) & 1);
  }
  void Ue(std::uint32_t v) {
    const std::uint64_t x = std::uint64_t{v} + 1;
    int n = 0;
    while ((x >> (n + 1)) != 0) ++n;
    U(n, 0);
    for (int i = n; i >= 0; --i) bits_.push_back((x >> i) & 1);
  }
  std::string Nal() {
    bits_.push_back(1);  // rbsp_stop_one_bit
    while (bits_.size() % 8) bits_.push_back(0);
    std::string rbsp;
    for (std::size_t i = 0; i < bits_.size(); i += 8) {
      std::uint8_t b = 0;
      for (int k = 0; k < 8; ++k) b = static_cast<std::uint8_t>(b << 1 | bits_[i + k]);
      rbsp.push_back(static_cast<char>(b));
    }
    std::string nal("\x00\x00\x00\x01\x67", 5);
    int zeros = 0;
    for (char c : rbsp) {
      if (zeros >= 2 && static_cast<std::uint8_t>(c) <= 3) {
        nal.push_back(3);
        zeros = 0;
      }
      nal.push_back(c);
      zeros = c == 0 ? zeros + 1 : 0;
    }
    return nal;
  }

 private:
  std::vector<int> bits_;
};

inline std::string Sps(std::uint32_t width_mbs, std::uint32_t height_mbs) {
  SpsWriter w;
  w.U(8, 66);  // Baseline
  w.U(8, 0);
  w.U(8, 51);
  w.Ue(0);  // seq_parameter_set_id
  w.Ue(0);  // log2_max_frame_num_minus4
  w.Ue(2);  // pic_order_cnt_type
  w.Ue(1);  // max_num_ref_frames
  w.U(1, 0);
  w.Ue(width_mbs - 1);
  w.Ue(height_mbs - 1);
  w.U(1, 1);  // frame_mbs_only_flag
  w.U(1, 1);
  w.U(1, 0);  // no cropping
  w.U(1, 0);  // no VUI
  return w.Nal();
}

}  // namespace cloudcast::testing
