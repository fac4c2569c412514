#include "daemon/training_format.hpp"

#include <algorithm>
#include <array>

#include "daemon/training_store.hpp"

namespace gearpulse::daemon::training_format {
namespace {

// Moves bytes from the front of `bytes` to `into` until it holds `size`; returns the bytes moved.
std::string_view fill_to(std::string& into, std::string_view& bytes, std::size_t size) {
  const std::string_view piece = bytes.substr(0, std::min(size - into.size(), bytes.size()));
  into.append(piece);
  bytes.remove_prefix(piece.size());
  return piece;
}

}  // namespace

std::uint32_t crc32_update(std::uint32_t crc, std::string_view data) noexcept {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k)
        c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  for (unsigned char byte : data)
    crc = table[(crc ^ byte) & 0xFFu] ^ (crc >> 8);
  return crc;
}

void NewestPairs::add(const Sample& s) {
  if (ring_.size() < keep_) {
    ring_.push_back(s);
    return;
  }
  if (keep_ == 0) return;
  ring_[oldest_] = s;
  oldest_ = (oldest_ + 1) % keep_;
}

std::deque<Sample> NewestPairs::in_order() const {
  std::deque<Sample> out(ring_.begin() + static_cast<std::ptrdiff_t>(oldest_), ring_.end());
  out.insert(out.end(), ring_.begin(), ring_.begin() + static_cast<std::ptrdiff_t>(oldest_));
  return out;
}

void StoreReader::feed(std::string_view bytes) {
  total_ += bytes.size();
  while (!bytes.empty()) {
    if (!header_read_) {
      fill(bytes, kHeaderSize, true);
      if (pending_.size() == kHeaderSize) {
        header_read_ = true;
        header_problem_ = check_header();
        pending_.clear();
      }
    } else if (!header_problem_.empty()) {
      return;  // the rest is only counted
    } else if (records_ < count_) {
      if (pending_.empty() && bytes.size() >= kRecordSize) {  // whole records, straight from the piece
        const std::uint64_t n = std::min<std::uint64_t>(bytes.size() / kRecordSize, count_ - records_);
        const std::string_view block = bytes.substr(0, static_cast<std::size_t>(n) * kRecordSize);
        crc_ = crc32_update(crc_, block);
        for (std::size_t at = 0; at < block.size(); at += kRecordSize)
          take(get_record(block, at));
        records_ += n;
        bytes.remove_prefix(block.size());
      } else {  // a record split between two pieces
        fill(bytes, kRecordSize, true);
        if (pending_.size() == kRecordSize) {
          take(get_record(pending_, 0));
          ++records_;
          pending_.clear();
        }
      }
    } else {
      fill(bytes, sizeof(std::uint32_t), false);  // the trailing checksum; what follows is only counted
      if (pending_.size() == sizeof(std::uint32_t)) return;
    }
  }
}

std::string StoreReader::finish() const {
  if (total_ < kHeaderSize + sizeof(std::uint32_t))
    return "file too short (" + std::to_string(total_) + " bytes)";
  if (!header_problem_.empty()) return header_problem_;
  const std::uint64_t body = total_ - kHeaderSize - sizeof(std::uint32_t);
  if (count_ > body / kRecordSize || count_ * kRecordSize != body)
    return "truncated or padded: header says " + std::to_string(count_) + " records, file holds " +
           std::to_string(body) + " bytes";
  if (stored_crc() != (crc_ ^ 0xFFFFFFFFu)) return "checksum mismatch";
  return {};
}

void StoreReader::fill(std::string_view& bytes, std::size_t size, bool checksummed) {
  const std::string_view piece = fill_to(pending_, bytes, size);
  if (checksummed) crc_ = crc32_update(crc_, piece);
}

std::string StoreReader::check_header() {
  if (std::memcmp(pending_.data(), kMagic, sizeof kMagic) != 0) return "not a training store (bad magic)";
  if (const auto version = get<std::uint32_t>(pending_, sizeof kMagic); version != kVersion)
    return "unsupported version " + std::to_string(version);
  if (const auto record = get<std::uint32_t>(pending_, sizeof kMagic + 4); record != kRecordSize)
    return "unexpected record size " + std::to_string(record);
  count_ = get<std::uint64_t>(pending_, sizeof kMagic + 8);
  return {};
}

void StoreReader::take(const Sample& s) {
  // The checksum is judged at the end; a record that is no pair (written by another program, or
  // corrupted before the checksum was taken) costs only itself.
  if (!plausible(s)) {
    ++skipped;
    return;
  }
  pairs.add(s);
}

void JournalReader::feed(std::string_view bytes) {
  total_ += bytes.size();
  while (!bytes.empty() && !broken_) {
    if (header_.size() < kJournalHeaderSize) {
      fill_to(header_, bytes, kJournalHeaderSize);
      continue;
    }
    fill_to(pending_, bytes, kJournalRecordSize);
    if (pending_.size() < kJournalRecordSize) return;  // the record's rest comes with the next piece
    const std::string_view record = std::string_view(pending_).substr(0, kRecordSize);
    if (get<std::uint32_t>(pending_, kRecordSize) != crc32(record)) {
      broken_ = true;
      return;
    }
    ++records_;
    const Sample s = get_record(pending_, 0);
    pending_.clear();
    // A whole record (its checksum holds) that is no pair: the records after it are sound, and kept.
    if (!plausible(s)) {
      if (skipped++ == 0) first_skipped = records_;
      continue;
    }
    ++recovered;
    pairs.add(s);
  }
}

std::string JournalReader::header_problem() const {
  if (total_ == 0) return "empty (nothing to recover)";
  if (header_.size() < kJournalHeaderSize ||
      std::memcmp(header_.data(), kJournalMagic, sizeof kJournalMagic) != 0)
    return "not a training journal (bad magic)";
  if (const auto version = get<std::uint32_t>(header_, sizeof kJournalMagic); version != kVersion)
    return "unsupported journal version " + std::to_string(version);
  return {};
}

std::uint32_t JournalReader::extends() const {
  return get<std::uint32_t>(header_, sizeof kJournalMagic + 4);
}

std::string JournalReader::tail_problem() const {
  const std::uint64_t left = total_ - kJournalHeaderSize - records_ * kJournalRecordSize;
  if (broken_)
    return "record " + std::to_string(records_ + 1) + " fails its checksum; it and the " +
           std::to_string(left) + " bytes from it on are dropped";
  if (left > 0) return std::to_string(left) + " bytes at the end are not a whole record (dropped)";
  return {};
}

}  // namespace gearpulse::daemon::training_format
