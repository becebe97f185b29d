// Stock PCLVisualizer (VTK) as the rendering reference for cloudcast-render-bench. PCL stays in
// pclvis_bench.cc, which is compiled without any AVX flag (see ../shared/PLATFORM.md): this
// header shows no PCL or Eigen type.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "cloudcast/core/point.h"

namespace cloudcast::bench {

class PclVisualizerBench {
 public:
  // Opens a PCLVisualizer window of `width` x `height` whose camera matches cloudcast's default
  // view (eye at the origin, looking along +z, y down, 60-degree vertical field of view), with
  // `point_size`-pixel points and the renderer's default background.
  PclVisualizerBench(int width, int height, float point_size);
  ~PclVisualizerBench();

  // Copies `clouds` into pcl::PointCloud<pcl::PointXYZRGBA> (untimed: in the paper's pipeline
  // the converter already produced PCL clouds) and adds the first with addPointCloud.
  void Prepare(const std::vector<const PointCloud*>& clouds);

  // One frame the way the paper's stock path ran: updatePointCloud(cloud k mod n, RGB field
  // handler) + spinOnce(1, true), then waits until VTK's render has completed. Milliseconds.
  // With VTK 9.1 on X11, spinOnce also runs vtkXRenderWindowInteractor::ProcessEvents, which
  // select()s until VTK's next timer when no X event is pending: under Xvfb that idles ~1 s.
  double Frame(std::size_t k);
  // The same without the event loop: updatePointCloud + the render window's Render() +
  // WaitForCompletion. What VTK itself needs to draw a new cloud.
  double FrameRenderOnly(std::size_t k);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::bench
