"""Training of the learned denoisers (``nca``, ``autoencoder``) on scenes rendered here."""
