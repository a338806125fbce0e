"use strict";
const fs = require("fs");
const path = require("path");

// An application's own certificate for the interoperability tests, made
// here rather than by node-opcua: OPC UA wants the application URI among the
// subject alternative names, and async-opcua wants it first, before the host
// names, which node-opcua's own certificates put first. Made in
// PKI/own/certs/certificate.pem (key PKI/own/private/private_key.pem) unless
// there.
async function ownCertificate(pkiDir, applicationUri, commonName) {
  const certFile = path.join(pkiDir, "own/certs/certificate.pem");
  const keyFile = path.join(pkiDir, "own/private/private_key.pem");
  if (fs.existsSync(certFile)) {
    return { certFile, keyFile };
  }
  const x509 = require("@peculiar/x509");
  const { webcrypto } = require("crypto");
  x509.cryptoProvider.set(webcrypto);
  const alg = { name: "RSASSA-PKCS1-v1_5", hash: "SHA-256", publicExponent: new Uint8Array([1, 0, 1]), modulusLength: 2048 };
  const keys = await webcrypto.subtle.generateKey(alg, true, ["sign", "verify"]);
  const cert = await x509.X509CertificateGenerator.createSelfSigned({
    name: `CN=${commonName}, O=cellwatch`,
    notBefore: new Date(Date.now() - 3600e3),
    notAfter: new Date(Date.now() + 365 * 24 * 3600e3),
    keys,
    signingAlgorithm: alg,
    extensions: [
      new x509.BasicConstraintsExtension(false, undefined, true),
      new x509.KeyUsagesExtension(
        x509.KeyUsageFlags.digitalSignature | x509.KeyUsageFlags.nonRepudiation |
          x509.KeyUsageFlags.keyEncipherment | x509.KeyUsageFlags.dataEncipherment, true),
      new x509.ExtendedKeyUsageExtension(["1.3.6.1.5.5.7.3.1", "1.3.6.1.5.5.7.3.2"]),
      new x509.SubjectAlternativeNameExtension([
        { type: "url", value: applicationUri },
        { type: "dns", value: "localhost" },
        { type: "ip", value: "127.0.0.1" },
      ]),
      await x509.SubjectKeyIdentifierExtension.create(keys.publicKey),
    ],
  });
  const pkcs8 = Buffer.from(await webcrypto.subtle.exportKey("pkcs8", keys.privateKey)).toString("base64");
  fs.mkdirSync(path.dirname(certFile), { recursive: true });
  fs.mkdirSync(path.dirname(keyFile), { recursive: true });
  fs.writeFileSync(certFile, cert.toString("pem") + "\n");
  fs.writeFileSync(keyFile, `-----BEGIN PRIVATE KEY-----\n${pkcs8.match(/.{1,64}/g).join("\n")}\n-----END PRIVATE KEY-----\n`);
  return { certFile, keyFile };
}

module.exports = { ownCertificate };
