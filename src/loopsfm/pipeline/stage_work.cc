// The work a rank other than rank 0 serves: every stage that shares its work.

#include <opencv2/core.hpp>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/segment_mapping.h"
#include "loopsfm/pipeline/work_sharing.h"

namespace loopsfm {

void ServeStageWork(Ranks& ranks, int num_threads) {
  // Parallelism is across frames and pairs; OpenCV's own threads would oversubscribe.
  cv::setNumThreads(1);
  ServeWork(ranks,
            {{WorkKind::kExtractSift, SiftWorkHandler()},
             {WorkKind::kMatchPairs, MatchWorkHandler()},
             {WorkKind::kMapSegment, SegmentWorkHandler()}},
            num_threads);
}

}  // namespace loopsfm
