// Example 07: the MC-COLMAP clip scheduler over your own SfM back end.
//
// schedule_clips() only needs a callable `sfm(FrameRange) -> result` whose result has status, message,
// frames, cameras and points (concept video3dgs::SfmBackend). Here a toy back end "succeeds" once a
// clip spans enough parallax (>= 12 frames in the first half of the video, >= 10 after), so the
// scheduler's growth, overlap and tail handling are visible. With the COLMAP adapter, pass a
// video3dgs::colmap::ColmapSfm instead (see README).
#include <cstdio>
#include <vector>

#include "video3dgs/scheduling.hpp"

struct ToyResult {
  video3dgs::SfmStatus status = video3dgs::SfmStatus::soft_failure;
  const char* message = "";
  std::vector<int> frames;
  std::vector<video3dgs::CameraD> cameras;
  std::vector<video3dgs::SfmPoint<double>> points;
};

int main() {
  const int frame_count = 50;
  auto toy_sfm = [&](video3dgs::FrameRange r) {
    ToyResult res;
    const int needed = r.first < frame_count / 2 ? 12 : 10;
    if (r.size() < needed) {
      res.message = "not enough parallax";
      return res;
    }
    res.status = video3dgs::SfmStatus::success;
    for (int f = r.first; f <= r.last; ++f) {
      res.frames.push_back(f);
      res.cameras.push_back(video3dgs::CameraD::from_fov(854, 480, 0.8));
    }
    res.points.resize(100);
    return res;
  };

  video3dgs::ScheduleOptions options;  // k = 10, overlap = 1
  options.progress = [](const video3dgs::ScheduleProgress& p) {
    std::printf("  clip %d: frames %2d-%2d -> %s\n", p.clip, p.range.first, p.range.last, video3dgs::to_string(p.status));
  };
  const auto schedule = video3dgs::schedule_clips(frame_count, toy_sfm, options);
  for (const auto& c : schedule.clips)
    std::printf("clip %2d-%2d: %d attempt(s), %zu frames registered\n", c.range.first, c.range.last, c.attempts,
                c.result.frames.size());
  std::printf("%d clips, %d attempts, %d soft failures\n", schedule.stats.clips, schedule.stats.attempts,
              schedule.stats.soft_failures);
  return 0;
}
