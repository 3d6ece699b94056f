#include "loopsfm/pipeline/ranks.h"

#include <deque>
#include <mutex>

namespace loopsfm {

RankMessage Ranks::Receive() {
  WaitBackoff backoff;
  while (true) {
    if (std::optional<RankMessage> message = TryReceive()) return std::move(*message);
    backoff.Wait();
  }
}

namespace {

struct Mailboxes {
  explicit Mailboxes(int size) : boxes(size) {}
  std::mutex mutex;
  std::vector<std::deque<RankMessage>> boxes;
};

class InProcessRank : public Ranks {
 public:
  InProcessRank(std::shared_ptr<Mailboxes> mailboxes, int rank)
      : mailboxes_(std::move(mailboxes)), rank_(rank) {}
  int Rank() const override { return rank_; }
  int Size() const override { return static_cast<int>(mailboxes_->boxes.size()); }
  int RanksOnThisMachine() const override { return Size(); }
  void Send(int to, int tag, std::string bytes) override {
    std::lock_guard<std::mutex> lock(mailboxes_->mutex);
    mailboxes_->boxes.at(to).push_back({rank_, tag, std::move(bytes)});
  }
  std::optional<RankMessage> TryReceive() override {
    std::lock_guard<std::mutex> lock(mailboxes_->mutex);
    std::deque<RankMessage>& box = mailboxes_->boxes[rank_];
    if (box.empty()) return std::nullopt;
    RankMessage message = std::move(box.front());
    box.pop_front();
    return message;
  }

 private:
  std::shared_ptr<Mailboxes> mailboxes_;
  int rank_;
};

}  // namespace

std::vector<std::unique_ptr<Ranks>> InProcessRanks(int size) {
  auto mailboxes = std::make_shared<Mailboxes>(size);
  std::vector<std::unique_ptr<Ranks>> ranks;
  for (int r = 0; r < size; ++r) ranks.push_back(std::make_unique<InProcessRank>(mailboxes, r));
  return ranks;
}

}  // namespace loopsfm
