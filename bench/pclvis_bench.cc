// PCL's own viewer, used the way PCL's tutorials and the paper's stock path use it. This file is
// the only one of cloudcast-render-bench that includes PCL (and with it Eigen and VTK).
#include "pclvis_bench.h"

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/visualization/pcl_visualizer.h>
#include <vtkRenderWindow.h>

#include <chrono>
#include <cmath>

namespace cloudcast::bench {

using PclCloud = pcl::PointCloud<pcl::PointXYZRGBA>;

struct PclVisualizerBench::Impl {
  pcl::visualization::PCLVisualizer viewer{"cloudcast-render-bench: PCLVisualizer", true};
  std::vector<PclCloud::Ptr> clouds;
  float point_size = 2.0f;
  bool added = false;
};

PclVisualizerBench::PclVisualizerBench(int width, int height, float point_size)
    : impl_(std::make_unique<Impl>()) {
  auto& v = impl_->viewer;
  v.setSize(width, height);
  v.setBackgroundColor(0.08, 0.08, 0.10);
  v.initCameraParameters();
  // cloudcast's default view: from the origin along +z, y down on screen.
  v.setCameraPosition(0, 0, 0, 0, 0, 1, 0, -1, 0);
  v.setCameraFieldOfView(60.0 * M_PI / 180.0);
  v.setCameraClipDistances(0.05, 200.0);
  v.setShowFPS(false);
  impl_->point_size = point_size;
}

PclVisualizerBench::~PclVisualizerBench() = default;

void PclVisualizerBench::Prepare(const std::vector<const PointCloud*>& clouds) {
  impl_->clouds.clear();
  for (const PointCloud* c : clouds) {
    PclCloud::Ptr p(new PclCloud);
    p->points.resize(c->size());
    bool dense = true;
    for (std::size_t i = 0; i < c->size(); ++i) {
      const Point& q = c->points[i];
      pcl::PointXYZRGBA& o = (*p)[i];
      o.x = q.x;
      o.y = q.y;
      o.z = q.z;
      o.rgba = q.rgba;
      dense = dense && std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z);
    }
    p->width = c->width != 0 ? c->width : static_cast<std::uint32_t>(c->size());
    p->height = c->height != 0 ? c->height : 1;
    p->is_dense = dense;
    impl_->clouds.push_back(p);
  }
  auto& v = impl_->viewer;
  if (impl_->added) v.removePointCloud("cloud");
  pcl::visualization::PointCloudColorHandlerRGBField<pcl::PointXYZRGBA> colour(impl_->clouds[0]);
  v.addPointCloud<pcl::PointXYZRGBA>(impl_->clouds[0], colour, "cloud");
  v.setPointCloudRenderingProperties(pcl::visualization::PCL_VISUALIZER_POINT_SIZE,
                                     impl_->point_size, "cloud");
  impl_->added = true;
  v.spinOnce(1, true);
}

double PclVisualizerBench::Frame(std::size_t k) {
  auto& v = impl_->viewer;
  const PclCloud::Ptr& cloud = impl_->clouds[k % impl_->clouds.size()];
  const auto t0 = std::chrono::steady_clock::now();
  pcl::visualization::PointCloudColorHandlerRGBField<pcl::PointXYZRGBA> colour(cloud);
  v.updatePointCloud<pcl::PointXYZRGBA>(cloud, colour, "cloud");
  v.spinOnce(1, true);
  // The same end point as cloudcast's glFinish: the frame is really rendered.
  v.getRenderWindow()->WaitForCompletion();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

double PclVisualizerBench::FrameRenderOnly(std::size_t k) {
  auto& v = impl_->viewer;
  const PclCloud::Ptr& cloud = impl_->clouds[k % impl_->clouds.size()];
  const auto t0 = std::chrono::steady_clock::now();
  pcl::visualization::PointCloudColorHandlerRGBField<pcl::PointXYZRGBA> colour(cloud);
  v.updatePointCloud<pcl::PointXYZRGBA>(cloud, colour, "cloud");
  v.getRenderWindow()->Render();
  v.getRenderWindow()->WaitForCompletion();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace cloudcast::bench
