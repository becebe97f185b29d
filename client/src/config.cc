#include "cloudcast/client/config.h"

namespace cloudcast::client {

void SetCamera(const CameraModel& camera, StreamConfig* config) {
  v1::CameraModel* c = config->mutable_camera();
  c->set_fx(camera.fx);
  c->set_fy(camera.fy);
  c->set_cx(camera.cx);
  c->set_cy(camera.cy);
  c->set_baseline(camera.baseline);
  c->set_disparity_scale(camera.disparity_scale);
  c->set_disparity_offset(camera.disparity_offset);
  // Set even when empty: an empty list means "no invalid values", unlike an absent one.
  v1::InvalidDisparities* invalid = c->mutable_invalid_disparities();
  invalid->clear_values();
  for (double v : camera.invalid_disparities) invalid->add_values(v);
}

void SetPassThrough(const PassThroughParams& params, StreamConfig* config) {
  v1::PassThroughConfig* p = config->mutable_passthrough();
  p->set_enabled(params.enabled);
  switch (params.axis) {
    case Axis::kX: p->set_axis(v1::AXIS_X); break;
    case Axis::kY: p->set_axis(v1::AXIS_Y); break;
    case Axis::kZ: p->set_axis(v1::AXIS_Z); break;
  }
  p->set_min(params.min);
  p->set_max(params.max);
  p->set_negative(params.negative);
}

void SetVoxelGrid(const VoxelGridParams& params, StreamConfig* config) {
  v1::VoxelGridConfig* v = config->mutable_voxel_grid();
  v->set_enabled(params.enabled);
  v->clear_leaf();
  v->set_leaf_x(params.leaf_x);
  v->set_leaf_y(params.leaf_y);
  v->set_leaf_z(params.leaf_z);
  v->set_min_points_per_voxel(params.min_points_per_voxel);
}

void SetDraco(const DracoOptions& options, StreamConfig* config) {
  v1::DracoConfig* d = config->mutable_draco();
  d->set_position_bits(options.position_bits);
  d->set_color_bits(options.color_bits);
  d->set_encode_speed(options.encode_speed);
  d->set_decode_speed(options.decode_speed);
  if (options.max_position_error > 0) {
    d->set_max_position_error(options.max_position_error);
  } else {
    d->clear_max_position_error();
  }
}

StreamConfig MakeStreamConfig(const PipelineOptions& options) {
  StreamConfig config;
  SetCamera(options.camera, &config);
  SetPassThrough(options.passthrough, &config);
  SetVoxelGrid(options.voxel, &config);
  return config;
}

}  // namespace cloudcast::client
