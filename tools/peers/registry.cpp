// The list of peers linked into this build (ours only when libcodec provides its public API).
#include "peers.h"

namespace peers {

std::unique_ptr<Peer> make_openjpeg_peer();
std::unique_ptr<Peer> make_htj2k_peer();
std::unique_ptr<Peer> make_jpegxl_peer();
std::unique_ptr<Peer> make_jpegxr_peer();
std::unique_ptr<Peer> make_charls_peer();
std::unique_ptr<Peer> make_lerc_peer();
std::unique_ptr<Peer> make_zfp_peer();
std::unique_ptr<Peer> make_zstd_peer();
#ifdef PEERS_HAVE_OURS
std::unique_ptr<Peer> make_ours_peer(uint32_t tile_size);
#endif

std::vector<std::unique_ptr<Peer>> all_peers() {
  std::vector<std::unique_ptr<Peer>> list;
#ifdef PEERS_HAVE_OURS
  list.push_back(make_ours_peer(64));
  list.push_back(make_ours_peer(256));
#endif
  list.push_back(make_openjpeg_peer());
  list.push_back(make_htj2k_peer());
  list.push_back(make_jpegxl_peer());
  list.push_back(make_jpegxr_peer());
  list.push_back(make_charls_peer());
  list.push_back(make_lerc_peer());
  list.push_back(make_zfp_peer());
  list.push_back(make_zstd_peer());
  return list;
}

}  // namespace peers
