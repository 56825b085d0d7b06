#pragma once
/// @file
/// `schedule_clips`: MC-COLMAP's clip scheduler as a generic algorithm over any SfM back end
/// (concept `SfmBackend`, scheduling/sfm_result.hpp).
///
/// Rule (after Video-3DGS, docs/method.md): a clip starts with k frames (default 10); while SfM fails
/// softly, the clip grows by one frame and SfM runs again; the next clip starts `overlap` frames
/// before the end of the previous one (default 1: it starts on the previous clip's last frame).
/// Beyond the reference:
///   - a video shorter than k gives one clip of all its frames;
///   - a short tail (fewer than k frames left) starts earlier so the last clip also has k frames
///     (`extend_short_tail`, never earlier than one frame after the previous clip's first frame);
///   - or, with `join_tail` = t in 1..k - overlap - 1, a clip whose first attempt would leave 1..t
///     frames after it reaches the last frame at once, if max_clip_frames allows, so no clip is
///     trained for a few frames the clip before it nearly covered (the tail's own clip would repeat
///     at least k - t of them). Growth stays one frame per attempt (a SfM back end may reuse the
///     attempt one frame shorter), so a clip that grows to within t frames of the end does not jump;
///   - a clip that fails at the end of the video grows backwards (its first frame moves earlier);
///   - growth stops at `max_clip_frames`, and `max_attempts` bounds the SfM calls of the whole
///     schedule. A clip that cannot succeed either raises `[sfm.no_reconstruction]` (default) or,
///     with `ClipFailurePolicy::keep_failed_clip`, is kept as a failed clip (its last attempt's
///     range and result, `succeeded == false`) and scheduling continues after it. An exhausted
///     attempt budget always raises `[sfm.attempt_budget]`; a `hard_error` result always raises
///     `[sfm.hard_error]`. Exceptions thrown by the back end propagate unchanged.
///
/// Guarantees: clips are contiguous, ordered, consecutive clips share at least `overlap` frames,
/// clip i+1 starts after clip i starts, and together the clips cover frames [0, frame_count).
/// Attempts per clip <= max_clip_frames - min(k, frame_count) + 1, so the schedule always ends.
///
/// Success of an attempt: the back end said `success`, (with `require_complete`, default) the
/// result registers every frame of the range and has at least one point, and it meets `quality`
/// (CameraQuality, scheduling/sfm_result.hpp: points per frame, mean reprojection error, mean track
/// length; off by default); a `success` that does not is treated as a soft failure, so the clip grows
/// (within `max_clip_frames` and `max_attempts`), and the progress message says what it missed.

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "video3dgs/core/error.hpp"
#include "video3dgs/scheduling/sfm_result.hpp"

namespace video3dgs {

/// What happens to a clip that cannot reach success within `max_clip_frames`.
enum class ClipFailurePolicy {
  throw_error,       ///< raise `[sfm.no_reconstruction]` naming the frames (default)
  keep_failed_clip,  ///< keep it with succeeded == false and go on with the next clip
};

/// Reported to `ScheduleOptions::progress` after every SfM attempt.
struct ScheduleProgress {
  int clip = 0;            ///< index of the clip being built
  FrameRange range;        ///< frames of this attempt
  int attempt = 0;         ///< 1-based attempt number within the clip
  int total_attempts = 0;  ///< attempts so far in the whole schedule
  SfmStatus status = SfmStatus::soft_failure;  ///< outcome as the scheduler judged it
  std::string message;     ///< the back end's message (and what `quality` found missing)
  double seconds = 0;      ///< wall time of this attempt
  int frames_done = 0;     ///< frames [0, frames_done) are covered by finished clips
  int frame_count = 0;
};

/// Reported to `ScheduleOptions::on_clip` when a clip is final (it never changes afterwards), before
/// the scheduler's next SfM attempt: a caller may start using the clip while later clips are still
/// being scheduled (the result is the back end's last one for `range`).
struct ScheduledClipInfo {
  int clip = 0;         ///< index in the schedule
  FrameRange range;     ///< frames of the clip (inclusive)
  int attempts = 0;     ///< SfM calls spent on it
  double seconds = 0;   ///< wall time of those calls
  bool succeeded = false;
};

struct ScheduleOptions {
  int initial_frames = 10;  ///< k: frames of a new clip (>= 1)
  int overlap = 1;          ///< frames shared by consecutive clips, 0 <= overlap < k
  int max_clip_frames = 0;  ///< longest clip (>= k); 0 = the whole video
  int max_attempts = 0;     ///< SfM calls allowed for the whole schedule; 0 = no budget
  bool extend_short_tail = true;  ///< the last clip starts earlier to have k frames
  /// 1..k - overlap - 1: a clip whose first attempt would leave 1..join_tail frames after it reaches
  /// the last frame instead (within max_clip_frames); 0: off, the tail gets a clip of its own (the
  /// method's rule). Larger values would swallow tails long enough for a clip of k frames.
  int join_tail = 0;
  bool require_complete = true;   ///< double-check success: all frames registered, >= 1 point
  CameraQuality quality{};        ///< what a success's cameras must rest on (default: nothing more)
  ClipFailurePolicy on_failure = ClipFailurePolicy::throw_error;
  std::function<void(const ScheduleProgress&)> progress;  ///< optional, called after every attempt
  std::function<void(const ScheduledClipInfo&)> on_clip;  ///< optional, called as each clip becomes final
};

/// A finished clip of the schedule.
template <class Result>
struct ScheduledClip {
  FrameRange range;      ///< frames of the clip (inclusive)
  int attempts = 0;      ///< SfM calls spent on this clip
  double seconds = 0;    ///< wall time of those calls
  bool succeeded = false;  ///< the scheduler's judgement (require_complete, quality)
  /// The successful result (or the last failed one), as the back end returned it: a clip kept failed
  /// because its "success" missed require_complete or quality still has result.status == success
  /// (the reason was in ScheduleProgress::message).
  Result result{};
};

struct ScheduleStats {
  int frame_count = 0;
  int clips = 0;
  int attempts = 0;        ///< SfM calls in total
  int soft_failures = 0;   ///< attempts that failed softly (incl. incomplete "successes" and quality misses)
  int grown_forward = 0;   ///< times a clip grew by one frame at its end
  int grown_backward = 0;  ///< times a clip grew by one frame at its start
  int failed_clips = 0;    ///< clips kept with succeeded == false
  double seconds = 0;      ///< wall time of all SfM calls
};

template <class Result>
struct ClipSchedule {
  std::vector<ScheduledClip<Result>> clips;
  ScheduleStats stats;
};

namespace detail {

inline void validate_schedule_options(int frame_count, const ScheduleOptions& o) {
  if (frame_count < 0) throw option_error("option.frame_count", "frame_count", "must be >= 0, got " + std::to_string(frame_count));
  if (o.initial_frames < 1)
    throw option_error("option.range", "initial_frames", "k must be >= 1, got " + std::to_string(o.initial_frames));
  if (o.overlap < 0 || o.overlap >= o.initial_frames)
    throw option_error("option.range", "overlap",
                       "must satisfy 0 <= overlap < k (k = " + std::to_string(o.initial_frames) + "), got " +
                           std::to_string(o.overlap));
  if (o.max_clip_frames != 0 && o.max_clip_frames < o.initial_frames)
    throw option_error("option.range", "max_clip_frames",
                       "must be 0 (no limit) or >= k = " + std::to_string(o.initial_frames) + ", got " +
                           std::to_string(o.max_clip_frames));
  if (o.max_attempts < 0)
    throw option_error("option.range", "max_attempts", "must be >= 0 (0 = no budget), got " + std::to_string(o.max_attempts));
  if (o.join_tail < 0 || o.join_tail > o.initial_frames - o.overlap - 1)
    throw option_error("option.range", "join_tail",
                       "must be in 0..k - overlap - 1 = " + std::to_string(o.initial_frames - o.overlap - 1) +
                           " (0 = off), got " + std::to_string(o.join_tail));
  const std::pair<const char*, double> limits[] = {{"quality.min_points_per_frame", o.quality.min_points_per_frame},
                                                   {"quality.max_reprojection_error", o.quality.max_reprojection_error},
                                                   {"quality.min_track_length", o.quality.min_track_length}};
  for (const auto& [name, v] : limits)
    if (!(v >= 0 && v <= 1e6))
      throw option_error("option.range", name, "must be in [0, 1e6] (0 = no limit), got " + std::to_string(v));
}

inline std::string range_name(FrameRange r) {
  return "frames " + std::to_string(r.first) + "-" + std::to_string(r.last);
}

/// Scheduler-side success check (see the file comment).
template <class Result>
bool attempt_succeeded(const Result& r, FrameRange range, bool require_complete) {
  if (r.status != SfmStatus::success) return false;
  if (!require_complete) return true;
  if (std::size(r.points) == 0) return false;
  std::vector<char> seen(static_cast<std::size_t>(range.size()), 0);
  for (const auto& f : r.frames) {
    const int frame = static_cast<int>(f);
    if (range.contains(frame)) seen[static_cast<std::size_t>(frame - range.first)] = 1;
  }
  return std::all_of(seen.begin(), seen.end(), [](char c) { return c != 0; });
}

}  // namespace detail

/// Splits a video of `frame_count` frames into clips on which `sfm` succeeds (see the file comment).
///
/// @param frame_count frames in the video (0 gives an empty schedule)
/// @param sfm         the back end, called as `sfm(FrameRange)`; it may keep state between calls
///                    (e.g. reuse the first clip's intrinsics)
/// @throws option_error `[option.*]` for invalid options; error `[sfm.hard_error]`,
///         `[sfm.no_reconstruction]`, `[sfm.attempt_budget]` as described above.
template <class Sfm>
[[nodiscard]] ClipSchedule<sfm_result_t<Sfm>> schedule_clips(int frame_count, Sfm&& sfm, const ScheduleOptions& options = {}) {
  static_assert(SfmBackend<Sfm>,
                "video3dgs::schedule_clips: the back end must be callable as sfm(video3dgs::FrameRange) and return "
                "a type with members status (SfmStatus), message (string), frames (range of int), cameras and "
                "points (sized ranges); see video3dgs/scheduling/sfm_result.hpp");
  using Result = sfm_result_t<Sfm>;
  detail::validate_schedule_options(frame_count, options);

  ClipSchedule<Result> schedule;
  ScheduleStats& st = schedule.stats;
  st.frame_count = frame_count;
  if (frame_count == 0) return schedule;

  const int n = frame_count;
  const int k = std::min(options.initial_frames, n);
  const int max_len = options.max_clip_frames == 0 ? n : std::min(options.max_clip_frames, n);
  int first = 0;
  int prev_first = -1;  // first frame of the previous clip

  for (;;) {
    FrameRange range{first, std::min(first + k - 1, n - 1)};
    if (options.extend_short_tail && range.size() < k) range.first = std::max(n - k, prev_first + 1);
    // join_tail: a first attempt leaving 1..join_tail frames after it reaches the last frame.
    if (const int left = n - 1 - range.last; options.join_tail > 0 && left > 0 && left <= options.join_tail && n - range.first <= max_len)
      range.last = n - 1;
    const int lowest_first = prev_first + 1;  // growing backwards never swallows the previous clip's start

    ScheduledClip<Result> clip;
    for (;;) {
      if (options.max_attempts > 0 && st.attempts >= options.max_attempts)
        throw error("sfm.attempt_budget", detail::range_name(range),
                    "the budget of " + std::to_string(options.max_attempts) +
                        " SfM attempts is exhausted before the video is covered (frames " + std::to_string(first) +
                        "-" + std::to_string(n - 1) + " remain); raise max_attempts or check the input");
      const auto t0 = std::chrono::steady_clock::now();
      Result result = sfm(range);
      const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ++st.attempts;
      ++clip.attempts;
      clip.seconds += secs;
      st.seconds += secs;

      SfmStatus judged = result.status;
      std::string message(result.message);
      if (judged == SfmStatus::success && !detail::attempt_succeeded(result, range, options.require_complete))
        judged = SfmStatus::soft_failure;
      if (judged == SfmStatus::success) {
        if (std::string why = camera_quality_shortfall(result, range, options.quality); !why.empty()) {
          judged = SfmStatus::soft_failure;
          message += (message.empty() ? "" : "; ") + ("cameras not trusted: " + why);
        }
      }
      if (judged == SfmStatus::soft_failure) ++st.soft_failures;
      if (options.progress) {
        ScheduleProgress p;
        p.clip = static_cast<int>(schedule.clips.size());
        p.range = range;
        p.attempt = clip.attempts;
        p.total_attempts = st.attempts;
        p.status = judged;
        p.message = message;
        p.seconds = secs;
        p.frames_done = judged == SfmStatus::success ? range.last + 1 : first;
        p.frame_count = n;
        options.progress(p);
      }
      if (judged == SfmStatus::hard_error)
        throw error("sfm.hard_error", detail::range_name(range), "SfM back end failed: " + std::string(result.message));

      clip.range = range;
      clip.result = std::move(result);
      if (judged == SfmStatus::success) {
        clip.succeeded = true;
        break;
      }
      // Soft failure: grow forwards while frames remain, then backwards; stop at max_len.
      if (range.size() < max_len && range.last < n - 1) {
        ++range.last;
        ++st.grown_forward;
        continue;
      }
      if (range.size() < max_len && range.first > lowest_first) {
        --range.first;
        ++st.grown_backward;
        continue;
      }
      if (options.on_failure == ClipFailurePolicy::throw_error)
        throw error("sfm.no_reconstruction", detail::range_name(range),
                    "SfM did not succeed after " + std::to_string(clip.attempts) + " attempts (clip of " +
                        std::to_string(range.size()) + " frames, max_clip_frames " + std::to_string(max_len) +
                        "); last message: " + message);
      ++st.failed_clips;
      break;
    }

    const FrameRange done = clip.range;
    if (options.on_clip) options.on_clip({static_cast<int>(schedule.clips.size()), clip.range, clip.attempts, clip.seconds, clip.succeeded});
    schedule.clips.push_back(std::move(clip));
    ++st.clips;
    if (done.last >= n - 1) break;
    prev_first = done.first;
    first = done.last - options.overlap + 1;
  }
  return schedule;
}

}  // namespace video3dgs
