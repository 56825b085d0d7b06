#include "video3dgs/scheduling.hpp"

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <doctest/doctest.h>

using namespace video3dgs;

namespace {

/// A minimal result type of our own (the scheduler is generic over it).
struct FakeResult {
  SfmStatus status = SfmStatus::soft_failure;
  std::string message;
  std::vector<int> frames;
  std::vector<int> cameras;
  std::vector<int> points;
};

/// Scripted back end: `decide(range)` says what happens; records every call.
struct ScriptedSfm {
  std::function<SfmStatus(FrameRange)> decide;
  std::vector<FrameRange> calls;
  FakeResult operator()(FrameRange r) {
    calls.push_back(r);
    FakeResult res;
    res.status = decide(r);
    if (res.status == SfmStatus::success) {
      for (int f = r.first; f <= r.last; ++f) res.frames.push_back(f);
      res.cameras.resize(res.frames.size());
      res.points = {1, 2, 3};
    } else {
      res.message = "scripted failure";
    }
    return res;
  }
};

/// A result that claims success for `r`, registering frames [from, r.last], with `points` points.
SfmResultD claimed_success(FrameRange r, int from, std::size_t points) {
  SfmResultD res;
  res.status = SfmStatus::success;
  res.range = r;
  for (int f = from; f <= r.last; ++f) {
    res.frames.push_back(f);
    res.cameras.emplace_back();
  }
  res.points.resize(points);
  return res;
}

static_assert(SfmBackend<ScriptedSfm>);
static_assert(SfmResultLike<SfmResultD>);
static_assert(!SfmBackend<int>);

/// Coverage invariants every schedule must satisfy.
template <class R>
void check_cover(const ClipSchedule<R>& s, int n, int overlap) {
  REQUIRE(!s.clips.empty());
  CHECK(s.clips.front().range.first == 0);
  CHECK(s.clips.back().range.last == n - 1);
  for (std::size_t i = 0; i < s.clips.size(); ++i) {
    const FrameRange r = s.clips[i].range;
    CHECK(r.first <= r.last);
    CHECK(r.first >= 0);
    CHECK(r.last < n);
    if (i > 0) {
      const FrameRange p = s.clips[i - 1].range;
      CHECK(r.first > p.first);                 // progress
      CHECK(r.first <= p.last - overlap + 1);   // at least `overlap` frames shared, no gap
      CHECK(r.last > p.last);
    }
  }
  CHECK(s.stats.clips == static_cast<int>(s.clips.size()));
  int attempts = 0;
  for (const auto& c : s.clips) attempts += c.attempts;
  CHECK(attempts == s.stats.attempts);
}

}  // namespace

TEST_CASE("schedule_clips: always-succeeding back end gives k-frame clips sharing one frame") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
  const auto s = schedule_clips(50, sfm);
  check_cover(s, 50, 1);
  // 0-9, 9-18, 18-27, 27-36, 36-45, then a short tail 45-49 extended back to 10 frames: 40-49.
  REQUIRE(s.clips.size() == 6);
  CHECK(s.clips[0].range == FrameRange{0, 9});
  CHECK(s.clips[1].range == FrameRange{9, 18});
  CHECK(s.clips[4].range == FrameRange{36, 45});
  CHECK(s.clips[5].range == FrameRange{40, 49});
  for (const auto& c : s.clips) {
    CHECK(c.succeeded);
    CHECK(c.attempts == 1);
    CHECK(c.result.frames.size() == static_cast<std::size_t>(c.range.size()));
  }
  CHECK(s.stats.attempts == 6);
  CHECK(s.stats.soft_failures == 0);
  CHECK(s.stats.grown_forward == 0);
  CHECK(s.stats.failed_clips == 0);
  CHECK(sfm.calls.size() == 6);
}

TEST_CASE("schedule_clips: without tail extension the last clip is the short remainder; overlap option") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
  ScheduleOptions o;
  o.extend_short_tail = false;
  const auto s = schedule_clips(50, sfm, o);
  check_cover(s, 50, 1);
  CHECK(s.clips.back().range == FrameRange{45, 49});

  ScriptedSfm sfm3{[](FrameRange) { return SfmStatus::success; }, {}};
  o.overlap = 3;
  o.initial_frames = 8;
  const auto s3 = schedule_clips(30, sfm3, o);
  check_cover(s3, 30, 3);
  CHECK(s3.clips[0].range == FrameRange{0, 7});
  CHECK(s3.clips[1].range == FrameRange{5, 12});

  ScriptedSfm sfm0{[](FrameRange) { return SfmStatus::success; }, {}};
  o.overlap = 0;
  const auto s0 = schedule_clips(16, sfm0, o);
  REQUIRE(s0.clips.size() == 2);
  CHECK(s0.clips[1].range == FrameRange{8, 15});
}

TEST_CASE("schedule_clips: join_tail lets the clip before a short tail take it in") {
  auto ranges = [](const auto& s) {
    std::vector<FrameRange> r;
    for (const auto& c : s.clips) r.push_back(c.range);
    return r;
  };
  ScheduleOptions o;
  o.join_tail = 4;
  {  // 36-45 would leave 46-49 (4 frames): one clip of 14 frames instead of 36-45 and 40-49.
    ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
    const auto s = schedule_clips(50, sfm, o);
    check_cover(s, 50, 1);
    CHECK(ranges(s) == std::vector<FrameRange>{{0, 9}, {9, 18}, {18, 27}, {27, 36}, {36, 49}});
    CHECK(s.stats.attempts == 5);
  }
  {  // 5 frames left is more than join_tail: the method's tail clip.
    ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
    const auto s = schedule_clips(51, sfm, o);
    check_cover(s, 51, 1);
    CHECK(s.clips.back().range == FrameRange{41, 50});
    CHECK(s.clips[s.clips.size() - 2].range == FrameRange{36, 45});
  }
  {  // The joined clip would be longer than max_clip_frames: no join.
    ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
    ScheduleOptions m = o;
    m.max_clip_frames = 13;
    const auto s = schedule_clips(50, sfm, m);
    check_cover(s, 50, 1);
    CHECK(s.clips.back().range == FrameRange{40, 49});
    for (const auto& c : s.clips) CHECK(c.range.size() <= 13);
  }
  {  // Only a first attempt joins: with clips that need 11 frames, 20-29 leaves 3 frames and is tried
     // as 20-32 at once; 20-29 in a 34-frame video leaves 4 (> 3), fails, and grows one frame (a SfM
     // back end may reuse the attempt one frame shorter) to 20-30, which succeeds; the tail is a clip.
    ScriptedSfm sfm{[](FrameRange r) { return r.size() >= 11 ? SfmStatus::success : SfmStatus::soft_failure; }, {}};
    ScheduleOptions g;
    g.join_tail = 3;
    const auto s = schedule_clips(33, sfm, g);
    check_cover(s, 33, 1);
    CHECK(ranges(s) == std::vector<FrameRange>{{0, 10}, {10, 20}, {20, 32}});
    CHECK(s.clips.back().attempts == 1);
    ScriptedSfm sfm34{[](FrameRange r) { return r.size() >= 11 ? SfmStatus::success : SfmStatus::soft_failure; }, {}};
    const auto s34 = schedule_clips(34, sfm34, g);
    check_cover(s34, 34, 1);
    CHECK(ranges(s34) == std::vector<FrameRange>{{0, 10}, {10, 20}, {20, 30}, {23, 33}});
    for (std::size_t i = 1; i < sfm34.calls.size(); ++i)  // every growth is one frame
      if (sfm34.calls[i].first == sfm34.calls[i - 1].first) CHECK(sfm34.calls[i].last == sfm34.calls[i - 1].last + 1);
  }
  // Every video length, tail and limit: the cover holds, no clip exceeds max_clip_frames, 0 is the
  // method's schedule, and otherwise the schedule is the method's with its last two clips replaced by
  // one from the second-last clip's first frame to the end exactly when that clip left 1..t frames
  // and fits max_clip_frames.
  for (int n = 1; n <= 45; ++n)
    for (int t = 0; t <= 8; ++t)
      for (int max_len : {0, 12}) {
        CAPTURE(n);
        CAPTURE(t);
        CAPTURE(max_len);
        ScheduleOptions a;
        a.max_clip_frames = max_len;
        ScheduleOptions b = a;
        b.join_tail = t;
        ScriptedSfm sa{[](FrameRange) { return SfmStatus::success; }, {}}, sb = sa;
        const auto plain = schedule_clips(n, sa, a), joined = schedule_clips(n, sb, b);
        check_cover(joined, n, 1);
        for (const auto& c : joined.clips) CHECK(c.range.size() <= (max_len == 0 ? n : max_len));
        std::vector<FrameRange> expected = ranges(plain);
        const std::size_t m = expected.size();
        if (t > 0 && m >= 2) {
          const FrameRange before = expected[m - 2];
          const int left = n - 1 - before.last;
          if (left >= 1 && left <= t && n - before.first <= (max_len == 0 ? n : max_len)) {
            expected.pop_back();
            expected.back().last = n - 1;
          }
        }
        CHECK(ranges(joined) == expected);
      }
  {  // Values outside 0..k - overlap - 1 are refused, naming the field; the limit itself is accepted.
    for (auto [value, overlap] : {std::pair{-1, 1}, std::pair{9, 1}, std::pair{8, 2}}) {
      ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
      ScheduleOptions bad;
      bad.join_tail = value;
      bad.overlap = overlap;
      CHECK_THROWS_WITH_AS((void)schedule_clips(20, sfm, bad), doctest::Contains("join_tail"), option_error);
      CHECK(sfm.calls.empty());
    }
    ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
    ScheduleOptions limit;
    limit.join_tail = 8;  // 0-9 leaves 10-17 (8 frames): one clip
    const auto s = schedule_clips(18, sfm, limit);
    CHECK(ranges(s) == std::vector<FrameRange>{{0, 17}});
  }
}

TEST_CASE("schedule_clips: fails until the clip has L frames, then grows one frame per attempt") {
  for (int L : {10, 11, 13, 17}) {
    INFO("L = " << L);
    ScriptedSfm sfm{[L](FrameRange r) { return r.size() >= L ? SfmStatus::success : SfmStatus::soft_failure; }, {}};
    std::vector<ScheduleProgress> seen;
    ScheduleOptions o;
    o.progress = [&](const ScheduleProgress& p) { seen.push_back(p); };
    std::vector<ScheduledClipInfo> final_clips;
    std::vector<std::size_t> calls_at_final, clip_calls_end;
    o.on_clip = [&](const ScheduledClipInfo& c) {
      final_clips.push_back(c);
      calls_at_final.push_back(sfm.calls.size());
    };
    const auto s = schedule_clips(60, sfm, o);
    check_cover(s, 60, 1);
    std::size_t calls = 0;
    for (const auto& c : s.clips) clip_calls_end.push_back(calls += std::size_t(c.attempts));
    for (const auto& c : s.clips) {
      CHECK(c.succeeded);
      CHECK(c.range.size() == L);  // never longer than needed (tail extended back to k, then grown)
    }
    // First clip: attempts with 10, 11, ..., L frames, all starting at 0.
    CHECK(s.clips[0].attempts == L - 10 + 1);
    for (int a = 0; a < s.clips[0].attempts; ++a) CHECK(sfm.calls[static_cast<std::size_t>(a)] == FrameRange{0, 9 + a});
    CHECK(s.stats.soft_failures == s.stats.attempts - s.stats.clips);
    CHECK(s.stats.grown_forward + s.stats.grown_backward == s.stats.soft_failures);
    REQUIRE(seen.size() == static_cast<std::size_t>(s.stats.attempts));
    CHECK(final_clips.size() == s.clips.size());
    for (std::size_t c = 0; c < final_clips.size() && c < s.clips.size(); ++c) {
      CHECK(final_clips[c].clip == int(c));
      CHECK(final_clips[c].range == s.clips[c].range);
      CHECK(final_clips[c].attempts == s.clips[c].attempts);
      CHECK(final_clips[c].succeeded);
      CHECK(calls_at_final[c] == clip_calls_end[c]);  // reported before the next clip's first attempt
    }
    CHECK(seen.back().status == SfmStatus::success);
    CHECK(seen.back().frames_done == 60);
    CHECK(seen.back().total_attempts == s.stats.attempts);
    CHECK(seen.front().attempt == 1);
  }
}

TEST_CASE("schedule_clips: a failing tail grows backwards") {
  // Any clip touching the last frame needs >= 14 frames; others succeed at once.
  const int n = 25;
  ScriptedSfm sfm{[n](FrameRange r) {
                    if (r.last == n - 1 && r.size() < 14) return SfmStatus::soft_failure;
                    return SfmStatus::success;
                  },
                  {}};
  const auto s = schedule_clips(n, sfm);
  check_cover(s, n, 1);
  // 0-9, 9-18, then 18-24 -> extended to 15-24 (10 frames), grown back to 11-24 (14 frames).
  REQUIRE(s.clips.size() == 3);
  CHECK(s.clips[2].range == FrameRange{11, 24});
  CHECK(s.clips[2].attempts == 5);
  CHECK(s.stats.grown_backward == 4);
  CHECK(s.stats.grown_forward == 0);
}

TEST_CASE("schedule_clips: backward growth never swallows the previous clip's first frame") {
  const int n = 20;
  ScriptedSfm sfm{[n](FrameRange r) { return r.last == n - 1 ? SfmStatus::soft_failure : SfmStatus::success; }, {}};
  ScheduleOptions o;
  o.on_failure = ClipFailurePolicy::keep_failed_clip;
  const auto s = schedule_clips(n, sfm, o);
  check_cover(s, n, 1);
  // 0-9, 9-18 succeed; the tail 18-19 is extended to 10-19 (k frames) and may not grow back past 10
  // (the previous clip starts at 9).
  REQUIRE(s.clips.size() == 3);
  CHECK(s.clips[1].succeeded);
  CHECK_FALSE(s.clips[2].succeeded);
  CHECK(s.clips[2].range == FrameRange{10, 19});
  CHECK(s.clips[2].attempts == 1);
  CHECK(s.stats.failed_clips == 1);
}

TEST_CASE("schedule_clips: a back end that always fails terminates with a clear error or a kept failed clip") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::soft_failure; }, {}};
  ScheduleOptions o;
  o.max_clip_frames = 15;
  try {
    (void)schedule_clips(40, sfm, o);
    FAIL("expected an error");
  } catch (const error& e) {
    CHECK(e.id() == "sfm.no_reconstruction");
    CHECK(e.where() == "frames 0-14");
    CHECK(std::string(e.what()).find("6 attempts") != std::string::npos);
  }
  CHECK(sfm.calls.size() == 6);  // 10, 11, ..., 15 frames

  // Without a length limit growth stops at the whole video (and grows no further back).
  ScriptedSfm sfm2{[](FrameRange) { return SfmStatus::soft_failure; }, {}};
  CHECK_THROWS_AS((void)schedule_clips(25, sfm2), error);
  CHECK(sfm2.calls.size() == 16);
  CHECK(sfm2.calls.back() == FrameRange{0, 24});

  // Fallback: failed clips are kept and the video is still covered.
  ScriptedSfm sfm3{[](FrameRange) { return SfmStatus::soft_failure; }, {}};
  o.on_failure = ClipFailurePolicy::keep_failed_clip;
  const auto s = schedule_clips(40, sfm3, o);
  check_cover(s, 40, 1);
  CHECK(s.stats.failed_clips == s.stats.clips);
  CHECK(s.stats.soft_failures == s.stats.attempts);
  for (const auto& c : s.clips) {
    CHECK_FALSE(c.succeeded);
    CHECK(c.range.size() <= 15);
    CHECK(c.result.message == "scripted failure");
  }

  // The attempt budget is a hard stop.
  ScriptedSfm sfm4{[](FrameRange) { return SfmStatus::soft_failure; }, {}};
  o.max_attempts = 7;
  try {
    (void)schedule_clips(40, sfm4, o);
    FAIL("expected an error");
  } catch (const error& e) {
    CHECK(e.id() == "sfm.attempt_budget");
  }
  CHECK(sfm4.calls.size() == 7);
}

TEST_CASE("schedule_clips: hard errors stop at once; exceptions propagate") {
  ScriptedSfm sfm{[](FrameRange r) { return r.first >= 9 ? SfmStatus::hard_error : SfmStatus::success; }, {}};
  try {
    (void)schedule_clips(30, sfm);
    FAIL("expected an error");
  } catch (const error& e) {
    CHECK(e.id() == "sfm.hard_error");
    CHECK(e.where() == "frames 9-18");
    CHECK(std::string(e.what()).find("scripted failure") != std::string::npos);
  }
  CHECK(sfm.calls.size() == 2);

  ScriptedSfm thrower{[](FrameRange) -> SfmStatus { throw external_error("colmap.missing", "colmap", "not installed"); }, {}};
  CHECK_THROWS_AS((void)schedule_clips(30, thrower), external_error);
}

TEST_CASE("schedule_clips: videos shorter than k, a 3-frame video, one frame, none") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
  const auto s = schedule_clips(3, sfm);
  REQUIRE(s.clips.size() == 1);
  CHECK(s.clips[0].range == FrameRange{0, 2});
  CHECK(s.stats.attempts == 1);

  ScriptedSfm fail{[](FrameRange) { return SfmStatus::soft_failure; }, {}};
  CHECK_THROWS_AS((void)schedule_clips(3, fail), error);
  CHECK(fail.calls.size() == 1);  // nothing to grow into

  ScriptedSfm one{[](FrameRange) { return SfmStatus::success; }, {}};
  const auto s1 = schedule_clips(1, one);
  REQUIRE(s1.clips.size() == 1);
  CHECK(s1.clips[0].range == FrameRange{0, 0});

  ScriptedSfm none{[](FrameRange) { return SfmStatus::success; }, {}};
  const auto s0 = schedule_clips(0, none);
  CHECK(s0.clips.empty());
  CHECK(none.calls.empty());

  // A video exactly k frames long, and k + 1 frames (the tail extension keeps the second clip at k).
  ScriptedSfm ten{[](FrameRange) { return SfmStatus::success; }, {}};
  CHECK(schedule_clips(10, ten).clips.size() == 1);
  ScriptedSfm eleven{[](FrameRange) { return SfmStatus::success; }, {}};
  const auto s11 = schedule_clips(11, eleven);
  REQUIRE(s11.clips.size() == 2);
  CHECK(s11.clips[1].range == FrameRange{1, 10});
}

TEST_CASE("schedule_clips: an incomplete 'success' counts as a soft failure") {
  // Claims success but drops the clip's first frame unless the clip has >= 12 frames.
  struct Partial {
    std::vector<FrameRange> calls;
    SfmResultD operator()(FrameRange r) {
      calls.push_back(r);
      return claimed_success(r, r.first + (r.size() >= 12 ? 0 : 1), 5);
    }
  } sfm;
  const auto s = schedule_clips(12, sfm);
  REQUIRE(s.clips.size() == 1);
  CHECK(s.clips[0].range == FrameRange{0, 11});
  CHECK(s.clips[0].attempts == 3);
  CHECK(s.clips[0].result.complete());
  CHECK(s.stats.soft_failures == 2);

  ScheduleOptions o;
  o.require_complete = false;
  Partial lax;
  CHECK(schedule_clips(12, lax, o).stats.attempts == 2);  // 0-9, then the tail 9-11 extended to 2-11
}

TEST_CASE("schedule_clips: invalid options are rejected with their field") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
  auto expect = [&](ScheduleOptions o, const char* field) {
    try {
      (void)schedule_clips(20, sfm, o);
      FAIL("expected option_error");
    } catch (const option_error& e) {
      CHECK(e.where() == field);
    }
  };
  ScheduleOptions o;
  o.initial_frames = 0;
  expect(o, "initial_frames");
  o = {};
  o.overlap = 10;
  expect(o, "overlap");
  o = {};
  o.overlap = -1;
  expect(o, "overlap");
  o = {};
  o.max_clip_frames = 5;
  expect(o, "max_clip_frames");
  o = {};
  o.max_attempts = -2;
  expect(o, "max_attempts");
  CHECK_THROWS_AS((void)schedule_clips(-1, sfm), option_error);
  CHECK(sfm.calls.empty());
}

namespace {

/// Scripted back end whose successes carry `points(range)` points of reprojection error
/// `error(range)` and track length 3: it always says success; the scheduler's quality rule judges.
struct QualitySfm {
  std::function<std::size_t(FrameRange)> points;
  std::function<double(FrameRange)> error;
  std::vector<FrameRange> calls;
  SfmResultD operator()(FrameRange r) {
    calls.push_back(r);
    SfmResultD res = claimed_success(r, r.first, points(r));
    for (auto& p : res.points) p.error = error(r), p.track_length = 3;
    return res;
  }
};

}  // namespace

TEST_CASE("schedule_clips: the camera-quality rule grows clips whose SfM 'succeeds' on too little") {
  SUBCASE("too few points per frame: the clip grows until it has enough") {
    // 11 points whatever the length, then 40 from 12 frames on: 2 per frame needs 20 (10 frames).
    QualitySfm sfm{[](FrameRange r) { return std::size_t(r.size() >= 12 ? 40 : 11); }, [](FrameRange) { return 0.5; }, {}};
    ScheduleOptions o;
    o.quality.min_points_per_frame = 2;
    std::vector<std::string> messages;
    o.progress = [&](const ScheduleProgress& p) { messages.push_back(p.message); };
    const auto s = schedule_clips(20, sfm, o);
    REQUIRE(s.clips.size() >= 1);
    CHECK(s.clips[0].range == FrameRange{0, 11});
    CHECK(s.clips[0].attempts == 3);
    CHECK(s.stats.soft_failures >= 2);
    REQUIRE(!messages.empty());
    CHECK(messages[0].find("11 3D points, fewer than 20") != std::string::npos);
    check_cover(s, 20, 1);
    // The method's rule (no quality limits) takes the 11-point clip at once.
    QualitySfm plain{sfm.points, sfm.error, {}};
    CHECK(schedule_clips(20, plain).clips[0].range == FrameRange{0, 9});
  }
  SUBCASE("a bad mean reprojection error: the clip grows until the error is acceptable") {
    QualitySfm sfm{[](FrameRange) { return std::size_t(500); }, [](FrameRange r) { return r.size() >= 11 ? 0.8 : 2.5; }, {}};
    ScheduleOptions o;
    o.quality.max_reprojection_error = 1.0;
    std::string first_message;
    o.progress = [&](const ScheduleProgress& p) {
      if (first_message.empty()) first_message = p.message;
    };
    const auto s = schedule_clips(10 + 9, sfm, o);
    CHECK(s.clips[0].range == FrameRange{0, 10});
    CHECK(first_message.find("mean reprojection error 2.5 px, above max_reprojection_error 1 px") != std::string::npos);
  }
  SUBCASE("short tracks are not trusted either") {
    QualitySfm sfm{[](FrameRange) { return std::size_t(500); }, [](FrameRange) { return 0.5; }, {}};
    ScheduleOptions o;
    o.quality.min_track_length = 4;  // every point has 3 observations: never met
    o.max_clip_frames = 12;
    o.on_failure = ClipFailurePolicy::keep_failed_clip;
    const auto s = schedule_clips(12, sfm, o);
    REQUIRE(s.clips.size() == 1);
    CHECK_FALSE(s.clips[0].succeeded);
  }
  SUBCASE("limits still bound the work: a rule SfM never meets ends in sfm.no_reconstruction after max_clip_frames") {
    QualitySfm sfm{[](FrameRange) { return std::size_t(5); }, [](FrameRange) { return 0.5; }, {}};
    ScheduleOptions o;
    o.quality.min_points_per_frame = 1;
    o.max_clip_frames = 13;
    try {
      (void)schedule_clips(30, sfm, o);
      FAIL("expected sfm.no_reconstruction");
    } catch (const error& e) {
      CHECK(e.id() == "sfm.no_reconstruction");
      CHECK(std::string(e.what()).find("cameras not trusted") != std::string::npos);
    }
    CHECK(sfm.calls.size() == 4);  // 10, 11, 12, 13 frames
    QualitySfm budget{sfm.points, sfm.error, {}};
    o.max_clip_frames = 0;
    o.max_attempts = 6;
    CHECK_THROWS_WITH_AS((void)schedule_clips(30, budget, o), doctest::Contains("6 SfM attempts"), error);
    CHECK(budget.calls.size() == 6);
  }
  SUBCASE("a result type without per-point errors is judged on its point count only") {
    ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};  // 3 points, no error member
    ScheduleOptions o;
    o.quality.max_reprojection_error = 1e-9;
    CHECK(schedule_clips(10, sfm, o).clips[0].succeeded);
    o.quality.min_points_per_frame = 1;  // 3 < 10
    o.max_clip_frames = 10;
    try {
      (void)schedule_clips(10, sfm, o);
      FAIL("expected sfm.no_reconstruction");
    } catch (const error& e) {
      CHECK(e.id() == "sfm.no_reconstruction");
    }
  }
}

TEST_CASE("schedule_clips: the camera-quality rule's limits are checked") {
  ScriptedSfm sfm{[](FrameRange) { return SfmStatus::success; }, {}};
  for (const char* field : {"quality.min_points_per_frame", "quality.max_reprojection_error", "quality.min_track_length"}) {
    ScheduleOptions o;
    const std::string f = field;
    double& v = f == "quality.min_points_per_frame" ? o.quality.min_points_per_frame
                : f == "quality.max_reprojection_error" ? o.quality.max_reprojection_error : o.quality.min_track_length;
    for (const double bad : {-1.0, std::nan(""), 1e7}) {
      v = bad;
      try {
        (void)schedule_clips(20, sfm, o);
        FAIL("expected option_error");
      } catch (const option_error& e) {
        CHECK(e.where() == f);
      }
    }
  }
}
